#include "sched.h"

volatile uint32_t sched_clock_count;
