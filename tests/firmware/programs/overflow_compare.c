/* A compare armed shortly before Timer3's overflow for counts 0-3 of the next period,
 * while the CPU runs 5-cycle instructions (call and ret) across the overflow: the chip
 * serves it right after the overflow; simavr 1.6 dropped it for the period when its
 * overflow callback ran later than the compare (firmware/sim/overflow_compares.c).
 * Timer1 (clk/8, one count each 8 cycles, a period of 524,288 cycles) measures how long
 * after its arming each compare came. Prints "trials N late L" on UART0, then idles. */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <stdint.h>

#define TRIALS 256

static volatile uint8_t hit;
static volatile uint16_t hit_at; /* TCNT1 in the compare's interrupt */

ISR(TIMER3_COMPA_vect)
{
    hit_at = TCNT1;
    hit = 1;
}

/* a call and a ret: 5 cycles each on the ATmega2560 */
static void __attribute__((noinline)) spin(void)
{
    __asm__ volatile("");
}

static void put(char c)
{
    while (!(UCSR0A & _BV(UDRE0)))
        ;
    UDR0 = (uint8_t)c;
}

static void put_u16(uint16_t v)
{
    char d[5];
    uint8_t n = 0;
    do {
        d[n++] = (char)('0' + v % 10);
        v /= 10;
    } while (v);
    while (n)
        put(d[--n]);
}

static void put_s(const char *s)
{
    while (*s)
        put(*s++);
}

int main(void)
{
    UBRR0 = 3; /* 250,000 baud */
    UCSR0B = _BV(TXEN0);
    TCCR1A = 0;
    TCCR1B = _BV(CS11); /* clk/8 */
    TCCR3A = 0;
    TCCR3B = _BV(CS30); /* clk/1, normal mode: the step engine's setting */
    TIMSK3 = _BV(OCIE3A);
    sei();
    uint16_t late = 0;
    for (uint16_t trial = 0; trial < TRIALS; trial++) {
        /* 1,000-4,000 cycles before the overflow (the compare far from the count) */
        while (TCNT3 < 61536u || TCNT3 > 64536u)
            ;
        uint16_t armed_at = TCNT1;
        hit = 0;
        OCR3A = trial & 3;
        /* the spin's phase against the overflow, a cycle apart from trial to trial (the
         * program is otherwise in step with the timer: each trial would be the same) */
        for (uint8_t d = (uint8_t)(trial >> 2); d; d--)
            __asm__ volatile("nop");
        if (trial & 0x80)
            __asm__ volatile("nop");
        while (!hit)
            spin();
        /* on time: under 5,000 cycles (625 counts of Timer1) after its arming; a period
         * late: over 65,536 (8,192 counts) */
        if ((uint16_t)(hit_at - armed_at) > 4096u)
            late++;
    }
    put_s("trials ");
    put_u16(TRIALS);
    put_s(" late ");
    put_u16(late);
    put('\n');
    for (;;)
        ;
}
