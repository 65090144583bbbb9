/* The very first code after reset (.init3, before the C runtime clears RAM): the heater
 * MOSFET gates low, the drivers the saved record holds enabled (their EN pins low, the
 * others high), the reset cause taken and the watchdog stopped (after a watchdog reset
 * the AVR keeps it running at its shortest period).
 *
 * Warm or cold is decided by the record in .noinit RAM, not by MCUSR: SRAM keeps its
 * content through a watchdog, external (DTR auto-reset) or brown-out reset and holds
 * noise after a power-on, so a record with the right magic and CRC-16 is one this
 * firmware wrote before the reset. The stk500v2 bootloader of a Mega 2560 reads MCUSR
 * and clears it before the application runs; what it leaves (Debian's arduino-core-avr
 * stk500boot_v2_mega2560.hex, disassembled):
 * - watchdog reset: it jumps to the application at once with the MCUSR it read still in
 *   r25 (WDRF set) and UART0 untouched (UCSR0B 0);
 *   But its start-up code sets EIND to 1, so that jump (an EICALL through a null pointer)
 *   lands at byte 0x20000, in erased flash: 0xFFFF executes as a skip that never skips,
 *   and the chip slides into the bootloader again, now with MCUSR 0, which takes the
 *   path below. The watchdog's cause is gone from the chip.
 * - any other reset: it waits about 1 s for a programmer on UART0, then jumps to the
 *   application with r25 = 0 and UART0's receiver and transmitter still enabled.
 * So the watchdog runs in interrupt-and-reset mode: its first time-out (1 s) interrupts,
 * and the interrupt drives the heater gates low and marks the record in .noinit; the
 * second (1 s later) resets. A marked record at boot is a watchdog reset (r25's WDRF too,
 * for a bootloader without that bug). The other causes come from the record: valid means
 * the RAM survived (an external reset, or a brown-out short enough to keep it: the chip
 * cannot tell them apart once MCUSR is cleared), invalid means a power-on. Without a
 * bootloader (ISP-flashed, or the harness's plain boot) MCUSR is read as it is. */
#include <stddef.h>

#include <avr/eeprom.h>
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/wdt.h>
#include <util/crc16.h>

#include "board_ramps14.h"
#include "protocol_gen.h"
#include "watchdog.h"

#define SAVED_MAGIC 0xC0DEu
#define STACK_PAINT 0xC5
#define CANARY 0xC0A7u /* at _end, the first byte above the static data */
#define CHECK_SEED 0x5A5Au
#define WDT_MARK 0xD06Bu /* the watchdog's interrupt came: its reset follows */

struct saved {
    uint16_t magic;
    uint32_t items_done, segments_done;
    uint16_t soft_boots;
    uint8_t enabled_mask; /* motors enabled when it was saved */
    uint16_t check;       /* CRC-16 (CCITT) of the bytes before it */
};

/* set in .init3, before the C runtime clears .bss: .noinit, all of them */
#define NOINIT __attribute__((section(".noinit")))
static uint8_t boot_r25 NOINIT;
static uint16_t wdt_mark NOINIT;
/* two copies, written one after the other: a reset in the middle of a write (an
 * external reset comes at any instruction) leaves the other one whole */
static struct saved saved[2] NOINIT;
static uint8_t boot_cause NOINIT, prev_valid NOINIT, prev_enabled NOINIT;
static uint32_t prev_items NOINIT, prev_segments NOINIT;
static uint16_t prev_soft NOINIT;
static uint32_t boot_id;
static uint32_t kicked_at;
static uint16_t EEMEM ee_boots;

static uint16_t check_of(const struct saved *s)
{
    const uint8_t *p = (const uint8_t *)s;
    uint16_t crc = CHECK_SEED;
    for (uint8_t i = 0; i < (uint8_t)offsetof(struct saved, check); i++)
        crc = _crc_ccitt_update(crc, p[i]);
    return crc;
}

static uint8_t copy_valid(const struct saved *s)
{
    return s->magic == SAVED_MAGIC && s->check == check_of(s);
}

/* the whole copy (the first when both are), or NULL */
static const struct saved *record_valid(void)
{
    return copy_valid(&saved[0]) ? &saved[0] : copy_valid(&saved[1]) ? &saved[1] : NULL;
}

static uint8_t cause_of(uint8_t mcusr, uint8_t r25, uint8_t uart_on, uint8_t valid)
{
    if (valid && wdt_mark == WDT_MARK)
        return BOOT_WATCHDOG;
    if (mcusr) { /* no bootloader cleared it */
        if (mcusr & _BV(PORF))
            return BOOT_POWER_ON;
        if (mcusr & _BV(BORF))
            return BOOT_BROWN_OUT;
        if (mcusr & _BV(WDRF))
            return BOOT_WATCHDOG;
        return BOOT_EXTERNAL_RESET; /* EXTRF, JTRF */
    }
    if (!uart_on && (r25 & _BV(WDRF)))
        return BOOT_WATCHDOG; /* the bootloader's watchdog path */
    if (uart_on) /* the bootloader waited: power-on, brown-out or external reset */
        return valid ? BOOT_EXTERNAL_RESET : BOOT_POWER_ON;
    return valid ? BOOT_SOFT_RESET : BOOT_POWER_ON; /* a jump to 0 */
}

/* the drivers held by the record: EN low (active low), every other EN high */
static void hold_drivers(uint8_t mask)
{
    if (mask & 1) X_EN_PORT &= (uint8_t)~_BV(X_EN_BIT); else X_EN_PORT |= _BV(X_EN_BIT);
    if (mask & 2) Y_EN_PORT &= (uint8_t)~_BV(Y_EN_BIT); else Y_EN_PORT |= _BV(Y_EN_BIT);
    if (mask & 4) Z_EN_PORT &= (uint8_t)~_BV(Z_EN_BIT); else Z_EN_PORT |= _BV(Z_EN_BIT);
    if (mask & 8) E_EN_PORT &= (uint8_t)~_BV(E_EN_BIT); else E_EN_PORT |= _BV(E_EN_BIT);
    X_EN_DDR |= _BV(X_EN_BIT);
    Y_EN_DDR |= _BV(Y_EN_BIT);
    Z_EN_DDR |= _BV(Z_EN_BIT);
    E_EN_DDR |= _BV(E_EN_BIT);
}

static void __attribute__((used, noinline)) early_boot(void)
{
    HOTEND_PORT &= (uint8_t)~_BV(HOTEND_BIT);
    BED_PORT &= (uint8_t)~_BV(BED_BIT);
    HOTEND_DDR |= _BV(HOTEND_BIT);
    BED_DDR |= _BV(BED_BIT);
    const struct saved *rec = record_valid();
    uint8_t valid = rec != NULL;
    hold_drivers(valid ? rec->enabled_mask & 0x0F : 0);
    uint8_t mcusr = MCUSR;
    MCUSR = 0;
    wdt_disable();
    uint8_t uart_on = UCSR0B & (_BV(RXEN0) | _BV(TXEN0));
    UCSR0B = 0; /* the bootloader's set-up, undone: uart_init configures it */
    boot_cause = cause_of(mcusr, boot_r25, uart_on, valid);
    wdt_mark = 0;
    prev_valid = valid;
    prev_items = valid ? rec->items_done : 0;
    prev_segments = valid ? rec->segments_done : 0;
    prev_enabled = valid ? rec->enabled_mask & 0x0F : 0;
    prev_soft = valid ? rec->soft_boots : 0;
    /* paint the gap between the static data and the stack: watchdog_stack_free() counts
     * what the stack never reached (the C runtime clears .bss after this, below _end) */
    extern uint8_t _end;
    volatile uint8_t *canary = &_end;
    canary[0] = (uint8_t)CANARY;
    canary[1] = (uint8_t)(CANARY >> 8);
    for (uint8_t *q = &_end + 2; q < (uint8_t *)SP - 8; q++)
        *q = STACK_PAINT;
}

uint8_t watchdog_canary_ok(void)
{
    extern uint8_t _end;
    const volatile uint8_t *canary = &_end;
    return canary[0] == (uint8_t)CANARY && canary[1] == (uint8_t)(CANARY >> 8);
}

/* r25 first (the bootloader's copy of MCUSR), before any compiled code can use it; the
 * stack pointer is set (.init2), so the rest is an ordinary call. */
void early_init(void) __attribute__((naked, used, section(".init3")));
void early_init(void)
{
    __asm__ __volatile__("sts %0, r25" ::"i"(&boot_r25));
    early_boot();
}

uint16_t watchdog_stack_free(void)
{
    extern uint8_t _end;
    const uint8_t *q = &_end + 2;
    while (q < (const uint8_t *)RAMEND && *q == STACK_PAINT)
        q++;
    return (uint16_t)(q - (&_end + 2));
}

uint8_t watchdog_boot_cause(void) { return boot_cause; }

void watchdog_start(void)
{
    uint16_t soft = prev_valid ? (uint16_t)(prev_soft + 1) : 0;
    uint16_t boots = eeprom_read_word(&ee_boots);
    if (!prev_valid) {
        boots++;
        eeprom_update_word(&ee_boots, boots);
    }
    boot_id = ((uint32_t)boots * 2654435761UL) ^ ((uint32_t)soft * 40503UL) ^ 0x5EEDUL;
    for (uint8_t i = 0; i < 2; i++) {
        saved[i].magic = SAVED_MAGIC;
        saved[i].soft_boots = soft;
        saved[i].items_done = 1; /* differs from the first save's: both are written */
    }
    watchdog_save(0, 0, prev_enabled);
    wdt_enable(WDTO_1S);
    WDTCSR |= _BV(WDIE); /* interrupt first, reset at the next time-out */
}

/* The first time-out: the main loop has not fed the watchdog for 1 s. Heaters off now,
 * the record marked; the reset follows 1 s later (WDIE is cleared by the hardware). */
ISR(WDT_vect)
{
    /* the timers' compare outputs disconnected (pwm.c), the pins driven low */
    HOTEND_PWM_TCCR &= (uint8_t)~HOTEND_PWM_COM;
    BED_PWM_TCCR &= (uint8_t)~BED_PWM_COM;
    HOTEND_PORT &= (uint8_t)~_BV(HOTEND_BIT);
    BED_PORT &= (uint8_t)~_BV(BED_BIT);
    wdt_mark = WDT_MARK;
}

/* Fed only while the scheduler's clock advances: a stopped step timer (whose
 * interrupt also counts down the heater lease) interrupts within 1 s (heaters
 * off) and resets the board within 2 s; the first code after the reset drives the heater
 * gates low. */
void watchdog_kick(uint32_t clock)
{
    if (clock != kicked_at) {
        kicked_at = clock;
        wdt_reset();
        if (!(WDTCSR & _BV(WDIE))) { /* a stall of over 1 s that ended: armed again */
            wdt_mark = 0;
            WDTCSR |= _BV(WDIE);
        }
    }
}

void watchdog_save(uint32_t items_done, uint32_t segments_done, uint8_t enabled_mask)
{
    if (saved[1].items_done == items_done && saved[1].segments_done == segments_done &&
        saved[1].enabled_mask == enabled_mask)
        return; /* unchanged: both copies already hold it */
    /* the first copy written and checked, then the second made from it: one CRC (both
     * copies hold the same bytes; the first is whole before the second is touched) */
    struct saved *s = &saved[0];
    s->items_done = items_done;
    s->segments_done = segments_done;
    s->enabled_mask = enabled_mask;
    s->check = check_of(s);
    saved[1] = *s;
}

uint8_t watchdog_prev_valid(void) { return prev_valid; }
uint8_t watchdog_prev_enabled(void) { return prev_enabled; }
uint32_t watchdog_prev_items(void) { return prev_items; }
uint32_t watchdog_prev_segments(void) { return prev_segments; }
uint32_t watchdog_boot_id(void) { return boot_id; }
