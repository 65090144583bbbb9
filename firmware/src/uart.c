/* USART0 driver. simavr takes the baud rate when UBRR0L is written, so U2X0 is
 * set before the divisor (the order is harmless on silicon). */
#include <avr/interrupt.h>
#include <avr/io.h>

#include "config.h"
#include "uart.h"

static volatile uint8_t rx_buf[UART_RX_SIZE];
static volatile uint8_t rx_head, rx_tail;
static volatile uint8_t tx_buf[UART_TX_SIZE];
static volatile uint16_t tx_head, tx_tail;
static volatile uint8_t rx_overruns;

void uart_init(void)
{
    UCSR0A = _BV(U2X0);
    UBRR0H = (uint8_t)(((F_CPU / (8UL * BAUD)) - 1) >> 8);
    UBRR0L = (uint8_t)((F_CPU / (8UL * BAUD)) - 1);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
}

ISR(USART0_RX_vect)
{
    uint8_t status = UCSR0A;
    uint8_t c = UDR0;
    uint8_t next = (uint8_t)(rx_head + 1) & (UART_RX_SIZE - 1);
    if (status & (_BV(DOR0) | _BV(FE0)))
        rx_overruns++;
    if (next == rx_tail) {
        rx_overruns++;
        return;
    }
    rx_buf[rx_head] = c;
    rx_head = next;
}

ISR(USART0_UDRE_vect)
{
    if (tx_head == tx_tail) {
        UCSR0B &= (uint8_t)~_BV(UDRIE0);
        return;
    }
    UDR0 = tx_buf[tx_tail];
    tx_tail = (tx_tail + 1) & (UART_TX_SIZE - 1);
}

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
    uint16_t head, tail;
    uint8_t s = SREG;
    cli();
    head = tx_head;
    tail = tx_tail;
    SREG = s;
    return (uint16_t)(UART_TX_SIZE - 1 - ((head - tail) & (UART_TX_SIZE - 1)));
}

void uart_write(const uint8_t *data, uint16_t len)
{
    while (len--) {
        uint16_t next = (tx_head + 1) & (UART_TX_SIZE - 1);
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
