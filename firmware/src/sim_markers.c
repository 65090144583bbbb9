#include "sim_markers.h"

uint8_t marker_edge_armed;

void markers_init(void)
{
    if (SIM_HOOKS) { /* the board build leaves D4, D6, D13 alone */
        MARK_EDGE_DDR |= _BV(MARK_EDGE_BIT);
        MARK_POS_DDR |= _BV(MARK_POS_BIT);
        MARK_ABORT_DDR |= _BV(MARK_ABORT_BIT);
    }
}
