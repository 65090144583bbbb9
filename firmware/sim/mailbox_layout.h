/* Byte offsets of the simulation mailbox (firmware/src/mailbox.h) that the harness reads
 * and writes. One definition for both sides: the firmware checks its struct against
 * them at compile time (_Static_assert in mailbox.h), the harness uses only these. */
#ifndef SIM_MAILBOX_LAYOUT_H
#define SIM_MAILBOX_LAYOUT_H

#define MB_MAGIC 0          /* "CDPR" */
#define MB_SEQ 4            /* u32 */
#define MB_POS 8            /* i32[4] */
#define MB_LAST_ERROR 24    /* u8 */
#define MB_ISR_MAX 26       /* u16 */
#define MB_LOST_STEPS 28    /* u16 */
#define MB_LOOP_MAX_US 30   /* u16 */
#define MB_SEGMENTS_PARSED 32 /* u32 */
#define MB_SPEEDUP_X16 36   /* u16, written by the harness */
#define MB_PLAN_STALLS 38   /* u16 */
#define MB_OVERRUNS 40      /* u16 */
#define MB_LINK_CLOCK 42    /* u32, written by the harness */
#define MB_LINK_VALID 46    /* u8, written by the harness */
#define MB_LATENCY_MAX 47   /* u8 */
#define MB_EDGE 48          /* u8 */
#define MB_LATE_PULSES 49   /* u16 */
#define MB_STACK_FREE 51    /* u16 */
#define MB_MOTION_TICKS 53  /* u32: the motion clock at the end of segment MB_SEQ */
#define MB_CANARY_AT 57     /* u16: the stack canary's address */
#define MB_SIZE 59

/* what the next MARK_EDGE toggle means (MB_EDGE) */
#define EDGE_SEG_END 0x01      /* a segment's last tick ended: MB_SEQ names it */
#define EDGE_MOTION_START 0x02 /* the first tick of motion begins */
#define EDGE_MOTION_STOP 0x04  /* the last tick of motion ended */

#endif
