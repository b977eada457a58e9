#ifndef TFC_UART_H_
#define TFC_UART_H_
void TFC_InitUARTs(void);
void TFC_UART_Process(void);
#endif
