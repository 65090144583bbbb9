/* The move queue's storage (queue.h): appended at head by the command layer, completed
 * at tail by the step interrupt. Here, below both, so neither names main.c. */
#include "queue.h"

struct item queue[QUEUE_SIZE];
volatile uint8_t queue_head, queue_tail;
