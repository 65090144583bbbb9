/* The simulator target's mailbox (sim_hooks.h): linked into build/cdpr-sim.elf
 * only, never into the board's build/cdpr.elf. */
#ifndef CDPR_SIM_HOOKS
#error "sim_hooks.c belongs to the simulator target only (make sim)"
#endif
#include "sim_hooks.h"

volatile struct sim_mailbox sim_mailbox;
