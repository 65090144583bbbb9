/* Session behaviour around the link: BOOT announcements, unsolicited
 * FLOW reports, the motion start rule and the host watchdog. */
#ifndef SESSION_H
#define SESSION_H
#include <stdint.h>

#include "config.h"

void session_opened(void);
void session_boot_on_data(void);
/* A HELLO before any session since this boot: BOOT goes out ahead of its IDENT. */
void session_boot_before_ident(void);
void session_poll(uint32_t now);
uint8_t session_may_start(void);
#if STEP_ENGINE
/* session_may_start's verdict as stepper_start_for holds it: the queue position it was
 * taken on when it allows the start, another one when it does not. */
uint8_t session_start_for(void);
#endif
uint8_t proto_flow(uint8_t *out); /* FLOW payload (struct link_upper.flow) */
void proto_frame_seen(void);      /* struct link_upper.frame_seen */

#endif
