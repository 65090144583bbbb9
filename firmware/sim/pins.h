/* The harness's view of board_ramps14.h (port letters and bits). */
#ifndef SIM_PINS_H
#define SIM_PINS_H

struct pin { char port; int bit; };

static const struct pin STEP_PINS[4] = {{'F', 0}, {'F', 6}, {'L', 3}, {'A', 4}};
static const struct pin DIR_PINS[4] = {{'F', 1}, {'F', 7}, {'L', 1}, {'A', 6}};
static const struct pin ENDSTOP_PINS[3] = {{'E', 5}, {'J', 1}, {'D', 3}};
static const struct pin LIMIT_PINS[3] = {{'E', 4}, {'J', 0}, {'D', 2}}; /* MAX sockets */
static const struct pin EN_PINS[4] = {{'D', 7}, {'F', 2}, {'K', 0}, {'A', 2}}; /* active low */
static const struct pin HEATER_PINS[2] = {{'B', 4}, {'H', 5}};
static const struct pin MARK_EDGE = {'B', 7}; /* OC1C */
static const struct pin MARK_POS = {'H', 3};
static const struct pin MARK_ABORT = {'G', 5};

#endif
