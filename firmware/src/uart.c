/* USART0 driver. simavr takes the baud rate when UBRR0L is written, so U2X0 is
 * set before the divisor (the order is harmless on silicon). */
#include <avr/interrupt.h>
#include <avr/io.h>

#include "config.h"
#include "uart.h"

/* (used: the interrupts' assembly names them) */
static volatile uint8_t rx_buf[UART_RX_SIZE] __attribute__((used));
static volatile uint8_t rx_head __attribute__((used)), rx_tail __attribute__((used));
static volatile uint8_t tx_buf[UART_TX_SIZE] __attribute__((used));
static volatile uint8_t tx_head __attribute__((used)), tx_tail __attribute__((used));
static volatile uint8_t rx_overruns __attribute__((used));

void uart_init(void)
{
    UCSR0A = _BV(U2X0);
    UBRR0H = (uint8_t)(((F_CPU / (8UL * BAUD)) - 1) >> 8);
    UBRR0L = (uint8_t)((F_CPU / (8UL * BAUD)) - 1);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
}

/* The UART's interrupts are hand-written: they run with interrupts masked, so every
 * cycle of theirs can delay a step's compare B (about 55 cycles each instead of the
 * compiler's 80). The rings are 256 bytes: their 8-bit indices wrap by themselves. */
_Static_assert(UART_RX_SIZE == 256 && UART_TX_SIZE == 256, "8-bit ring indices");

/* A received byte into the ring; a UART error or a full ring counted as an overrun
 * (status read before the data register, as the datasheet asks). */
ISR(USART0_RX_vect, ISR_NAKED)
{
    __asm__ volatile(
        "push r24\n\t"
        "in r24, __SREG__\n\t"
        "push r24\n\t"
        "push r25\n\t"
        "push r30\n\t"
        "push r31\n\t"
        "lds r25, %[ucsra]\n\t"
        "lds r24, %[udr]\n\t"
        "andi r25, %[errs]\n\t"
        "breq 1f\n\t"
        "lds r25, rx_overruns\n\t"
        "inc r25\n\t"
        "sts rx_overruns, r25\n"
        "1:\n\t"
        "lds r30, rx_head\n\t"
        "mov r25, r30\n\t"
        "inc r25\n\t"
        "lds r31, rx_tail\n\t"
        "cp r25, r31\n\t"
        "breq 2f\n\t" /* full: the byte is lost, counted */
        "ldi r31, 0\n\t"
        "subi r30, lo8(-(rx_buf))\n\t"
        "sbci r31, hi8(-(rx_buf))\n\t"
        "st Z, r24\n\t"
        "sts rx_head, r25\n\t"
        "rjmp 3f\n"
        "2:\n\t"
        "lds r25, rx_overruns\n\t"
        "inc r25\n\t"
        "sts rx_overruns, r25\n"
        "3:\n\t"
        "pop r31\n\t"
        "pop r30\n\t"
        "pop r25\n\t"
        "pop r24\n\t"
        "out __SREG__, r24\n\t"
        "pop r24\n\t"
        "reti\n\t" ::[ucsra] "n"(_SFR_MEM_ADDR(UCSR0A)),
        [udr] "n"(_SFR_MEM_ADDR(UDR0)), [errs] "M"(_BV(DOR0) | _BV(FE0)));
}

/* Both UDRE handlers' sending of the byte at tx_tail (r30 holds tx_tail; r24 and r31
 * are free): into UDR0, and the tail moved on. */
#define UDRE_SEND_NEXT                                                                        \
    "ldi r31, 0\n\t"                                                                         \
    "subi r30, lo8(-(tx_buf))\n\t"                                                           \
    "sbci r31, hi8(-(tx_buf))\n\t"                                                           \
    "ld r24, Z\n\t"                                                                          \
    "sts %[udr], r24\n\t"                                                                    \
    "lds r24, tx_tail\n\t"                                                                   \
    "inc r24\n\t"                                                                            \
    "sts tx_tail, r24\n\t"

#if STEP_ENGINE
/* The next byte to send, or the interrupt left off when the ring is empty. Its own
 * enable off first, then interrupts on: USART0's vectors outrank the steppers' compares,
 * and a FLOW report sent across a segment's boundary (where every stepper takes its next
 * chunk) held a stepper's pending compare for whole handlers (its edges 10-27 us late);
 * now a due compare waits about 12 cycles. The enable comes back masked at the end, when
 * a byte went out (simavr raises the interrupt again once the byte has left, or at once
 * if it left while the enable was off). */
ISR(USART0_UDRE_vect, ISR_NAKED)
{
    __asm__ volatile(
        "push r24\n\t"
        "in r24, __SREG__\n\t"
        "push r24\n\t"
        "lds r24, %[ucsrb]\n\t"
        "andi r24, %[noudrie]\n\t"
        "sts %[ucsrb], r24\n\t"
        "sei\n\t"
        "push r30\n\t"
        "push r31\n\t"
        "lds r30, tx_tail\n\t"
        "lds r24, tx_head\n\t"
        "cp r30, r24\n\t"
        "breq 2f\n\t" /* empty: the enable stays off (uart_write sets it) */
        UDRE_SEND_NEXT
        "pop r31\n\t"
        "pop r30\n\t"
        /* masked from here: on the chip the flag is up again at once when the byte
         * went straight to the shift register, and the next byte waits for this reti */
        "cli\n\t"
        "lds r24, %[ucsrb]\n\t"
        "ori r24, %[udrie]\n\t"
        "sts %[ucsrb], r24\n\t"
        "rjmp 3f\n"
        "2:\n\t"
        "pop r31\n\t"
        "pop r30\n"
        "3:\n\t"
        "pop r24\n\t"
        "out __SREG__, r24\n\t"
        "pop r24\n\t"
        "reti\n\t" ::[ucsrb] "n"(_SFR_MEM_ADDR(UCSR0B)),
        [udr] "n"(_SFR_MEM_ADDR(UDR0)), [noudrie] "M"(0xFF ^ _BV(UDRIE0)),
        [udrie] "M"(_BV(UDRIE0)));
}
#else
/* The next byte to send, or the interrupt off when the ring is empty. */
ISR(USART0_UDRE_vect, ISR_NAKED)
{
    __asm__ volatile(
        "push r24\n\t"
        "in r24, __SREG__\n\t"
        "push r24\n\t"
        "push r30\n\t"
        "push r31\n\t"
        "lds r30, tx_tail\n\t"
        "lds r24, tx_head\n\t"
        "cp r30, r24\n\t"
        "brne 1f\n\t"
        "lds r24, %[ucsrb]\n\t"
        "andi r24, %[noudrie]\n\t"
        "sts %[ucsrb], r24\n\t"
        "rjmp 2f\n"
        "1:\n\t"
        UDRE_SEND_NEXT
        "2:\n\t"
        "pop r31\n\t"
        "pop r30\n\t"
        "pop r24\n\t"
        "out __SREG__, r24\n\t"
        "pop r24\n\t"
        "reti\n\t" ::[ucsrb] "n"(_SFR_MEM_ADDR(UCSR0B)),
        [udr] "n"(_SFR_MEM_ADDR(UDR0)), [noudrie] "M"(0xFF ^ _BV(UDRIE0)));
}
#endif

uint16_t uart_read(uint8_t *dst, uint16_t max)
{
    /* the ring's indices once: the interrupt only appends */
    uint8_t head = rx_head, tail = rx_tail;
    uint16_t n = 0;
    while (tail != head && n < max) {
        dst[n++] = rx_buf[tail];
        tail = (uint8_t)(tail + 1) & (UART_RX_SIZE - 1);
    }
    rx_tail = tail;
    return n;
}

uint16_t uart_tx_free(void)
{
    /* one-byte indices: each read is atomic, the interrupt only advances the tail */
    uint8_t used = (uint8_t)(tx_head - tx_tail);
    return (uint16_t)(UART_TX_SIZE - 1 - used);
}

void uart_write(const uint8_t *data, uint16_t len)
{
    while (len--) {
        uint8_t next = (uint8_t)(tx_head + 1);
        if (next == tx_tail)
            break; /* the caller checked the room; never block */
        tx_buf[tx_head] = *data++;
        tx_head = next;
    }
    UCSR0B |= _BV(UDRIE0);
}

uint8_t uart_rx_overruns(void)
{
    return rx_overruns;
}
