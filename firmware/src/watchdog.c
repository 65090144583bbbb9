/* The very first code after reset (.init3, before the C runtime clears RAM)
 * drives the heater MOSFET gates low, takes MCUSR and stops the watchdog: after
 * a watchdog reset the AVR keeps it running at its shortest period. */
#include <avr/eeprom.h>
#include <avr/io.h>
#include <avr/wdt.h>

#include "board_ramps14.h"
#include "protocol_gen.h"
#include "watchdog.h"

#define SAVED_MAGIC 0xC0DEu
#define STACK_PAINT 0xC5

struct saved {
    uint16_t magic;
    uint32_t items_done, segments_done;
    uint16_t soft_boots;
    uint8_t enabled_mask; /* motors enabled when it was saved */
    uint16_t check;
};

static uint8_t mcusr_at_boot __attribute__((section(".noinit")));
static struct saved saved __attribute__((section(".noinit")));
static uint8_t prev_valid;
static uint32_t prev_items, prev_segments, boot_id;
static uint8_t prev_enabled;
static uint32_t kicked_at;
static uint16_t EEMEM ee_boots;

void early_init(void) __attribute__((naked, used, section(".init3")));
void early_init(void)
{
    HOTEND_PORT &= (uint8_t)~_BV(HOTEND_BIT);
    BED_PORT &= (uint8_t)~_BV(BED_BIT);
    HOTEND_DDR |= _BV(HOTEND_BIT);
    BED_DDR |= _BV(BED_BIT);
    mcusr_at_boot = MCUSR;
    MCUSR = 0;
    wdt_disable();
    /* paint the gap between the static data and the stack: watchdog_stack_free() counts
     * what the stack never reached (the C runtime clears .bss after this, below _end) */
    extern uint8_t _end;
    for (uint8_t *q = &_end; q < (uint8_t *)SP - 4; q++)
        *q = STACK_PAINT;
}

uint16_t watchdog_stack_free(void)
{
    extern uint8_t _end;
    const uint8_t *q = &_end;
    while (q < (const uint8_t *)RAMEND && *q == STACK_PAINT)
        q++;
    return (uint16_t)(q - &_end);
}

static uint16_t check_of(const struct saved *s)
{
    return (uint16_t)(s->magic ^ (uint16_t)s->items_done ^ (uint16_t)(s->items_done >> 16) ^
                      (uint16_t)s->segments_done ^ (uint16_t)(s->segments_done >> 16) ^
                      s->soft_boots ^ s->enabled_mask ^ 0x5A5A);
}

uint8_t watchdog_boot_cause(void)
{
    if (mcusr_at_boot & _BV(WDRF))
        return BOOT_WATCHDOG;
    if (mcusr_at_boot & (_BV(PORF) | _BV(BORF)))
        return BOOT_POWER_ON;
    return mcusr_at_boot & _BV(EXTRF) ? BOOT_SOFT_RESET : BOOT_POWER_ON;
}

void watchdog_start(void)
{
    uint8_t cause = watchdog_boot_cause();
    uint8_t valid = saved.magic == SAVED_MAGIC && saved.check == check_of(&saved);
    prev_valid = valid && cause != BOOT_POWER_ON;
    if (prev_valid) {
        prev_items = saved.items_done;
        prev_segments = saved.segments_done;
        prev_enabled = saved.enabled_mask & 0x0F;
    }
    uint16_t soft = valid ? (uint16_t)(saved.soft_boots + 1) : 0;
    uint16_t boots = eeprom_read_word(&ee_boots);
    if (!prev_valid) {
        boots++;
        eeprom_update_word(&ee_boots, boots);
    }
    boot_id = ((uint32_t)boots * 2654435761UL) ^ ((uint32_t)soft * 40503UL) ^ 0x5EEDUL;
    saved.magic = SAVED_MAGIC;
    saved.soft_boots = soft;
    watchdog_save(0, 0, prev_enabled);
    wdt_enable(WDTO_2S);
}

/* Fed only while the scheduler's clock advances: a stopped step timer (whose
 * interrupt also runs the heaters' PWM and their lease) resets the board within
 * 2 s, and the first code after the reset drives the heater gates low. */
void watchdog_kick(uint32_t clock)
{
    if (clock != kicked_at) {
        kicked_at = clock;
        wdt_reset();
    }
}

void watchdog_save(uint32_t items_done, uint32_t segments_done, uint8_t enabled_mask)
{
    saved.items_done = items_done;
    saved.segments_done = segments_done;
    saved.enabled_mask = enabled_mask;
    saved.check = check_of(&saved);
}

uint8_t watchdog_prev_valid(void) { return prev_valid; }
uint8_t watchdog_prev_enabled(void) { return prev_enabled; }
uint32_t watchdog_prev_items(void) { return prev_items; }
uint32_t watchdog_prev_segments(void) { return prev_segments; }
uint32_t watchdog_boot_id(void) { return boot_id; }
