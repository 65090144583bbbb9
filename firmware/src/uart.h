/* USART0 at BAUD, 8N1, interrupt driven ring buffers both ways. */
#ifndef UART_H
#define UART_H
#include <stdint.h>

#define UART_RX_SIZE 256 /* power of two */
#define UART_TX_SIZE 256 /* power of two */

void uart_init(void);
/* Up to max received bytes into dst (one call for a main-loop turn's bytes: a call
 * per byte cost more than the copy); returns how many. */
uint16_t uart_read(uint8_t *dst, uint16_t max);
uint16_t uart_tx_free(void);
void uart_write(const uint8_t *data, uint16_t len); /* caller checks uart_tx_free() */
uint8_t uart_rx_overruns(void);

#endif
