/* Host commands: the layer above the link (PROTOCOL.md sections 4 and 8). */
#ifndef COMMANDS_H
#define COMMANDS_H
#include <stdint.h>

/* A DATA frame in order (struct link_upper.accept). */
uint8_t proto_accept(const uint8_t *payload, uint8_t len);
/* An URGENT frame (struct link_upper.urgent). */
void proto_urgent(const uint8_t *payload, uint8_t len);
/* Execute messages of the held frames, oldest first, for about `units` clock units
 * (at least one message), preparing plans between them. */
void proto_execute(uint16_t units);
/* Queue items of acknowledged frames not queued yet (not free for the host). */
uint8_t proto_pending_items(void);
/* A new session: the coder context and the held frames are forgotten. */
void commands_reset_session(void);

#endif
