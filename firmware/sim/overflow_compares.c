/* The compares simavr 1.6 drops just after a 16-bit timer's overflow.
 *
 * simavr runs a timer's overflow as a cycle timer (avr_timer_tov, avr_timer.c), and that
 * callback is what schedules the new period's compares. It runs after the instruction in
 * progress at the overflow has ended, up to 4 cycles late (call, ret and reti take 5 on
 * the ATmega2560), and it schedules a compare only if `comp_cycles >= avr->cycle - when`
 * (comp_cycles is OCR + 1): a compare at counts 0-3 of the new period, armed before the
 * overflow, is dropped for that period and served a whole period (65,536 cycles, 4.1 ms at
 * clk/1) late, or later still if the next overflow's callback is late again. The chip
 * matches TCNT == OCR at every count, 0 included: there the compare comes on time. (The
 * same test is still in simavr's avr_timer_tov after 1.6, up to its master of July 2026.)
 *
 * Here a cycle timer of our own runs at each of the timer's overflows, in the same pass of
 * simavr's cycle timers as its overflow callback (same `when`, same avr->cycle, no
 * instruction between them), applies simavr's test to each compare's comp_cycles (read
 * from simavr's own timer state, avr_timer.h) and raises each dropped compare's interrupt
 * (its flag; its vector when enabled) at once: 1-4 cycles after the chip would. Only the
 * step engine's Timer3 and Timer5 are watched (firmware/src/step_engine.c), while they run
 * in normal mode. */
#include "overflow_compares.h"

#include <avr_timer.h>
#include <sim_cycle_timers.h>
#include <sim_interrupts.h>
#include <sim_io.h>
#include <string.h>

unsigned overflow_compares_served;

static avr_timer_t *timer_named(avr_t *avr, char name)
{
    for (avr_io_t *io = avr->io_port; io; io = io->next)
        if (io->kind && !strcmp(io->kind, "timer") && ((avr_timer_t *)io)->name == name)
            return (avr_timer_t *)io; /* (its avr_io_t is its first member) */
    return NULL;
}

static avr_timer_t *watched[2];

/* its clock on (a reset stops it and leaves tov_cycles as it was) in normal mode */
static int counting(avr_t *avr, avr_timer_t *p)
{
    return p->tov_cycles > 1 && p->wgm_op_mode_kind == avr_timer_wgm_normal &&
           avr_regbit_get_array(avr, p->cs, ARRAY_SIZE(p->cs)) != 0;
}

/* at `when`, a cycle of the timer's overflow: the compares simavr's callback dropped */
static avr_cycle_count_t at_overflow(avr_t *avr, avr_cycle_count_t when, void *param)
{
    avr_timer_t *p = param;
    if (!counting(avr, p))
        return 0; /* stopped or another mode: overflow_compares_poll starts it again */
    /* (simavr's own callback at the same `when` may have run before this one or not) */
    if (p->tov_base != when && p->tov_base + p->tov_cycles != when)
        return 0; /* its count moved (TCNT written): taken up again from the new base */
    avr_cycle_count_t late = avr->cycle - when;
    for (int c = 0; c < AVR_TIMER_COMP_COUNT; c++) {
        uint64_t cycles = p->comp[c].comp_cycles;
        if (cycles && cycles < p->tov_cycles && cycles < late) {
            /* (the flag as on the chip, enabled or not: a stopped stepper's compare
             * left at 0 matches each period there too) */
            avr_raise_interrupt(avr, &p->comp[c].interrupt);
            if (avr_regbit_get(avr, p->comp[c].interrupt.enable))
                overflow_compares_served++;
        }
    }
    return when + p->tov_cycles;
}

void overflow_compares_init(avr_t *avr)
{
    watched[0] = timer_named(avr, '3');
    watched[1] = timer_named(avr, '5');
}

void overflow_compares_poll(avr_t *avr)
{
    for (int i = 0; i < 2; i++) {
        avr_timer_t *p = watched[i];
        if (!p || !counting(avr, p) || avr_cycle_timer_status(avr, at_overflow, p))
            continue;
        /* the next overflow (its base is the last one's cycle: between two instructions
         * the next one is still ahead) */
        avr_cycle_count_t next = p->tov_base + p->tov_cycles;
        if (next > avr->cycle)
            avr_cycle_timer_register(avr, next - avr->cycle, at_overflow, p);
    }
}
