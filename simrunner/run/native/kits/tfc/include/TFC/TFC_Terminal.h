/* TFC_Terminal.h (simulator): TERMINAL_PRINTF prints to the program's standard output. */
#ifndef TFC_TERMINAL_H_
#define TFC_TERMINAL_H_
#include <stdio.h>
#define TERMINAL_PRINTF(...) printf(__VA_ARGS__)
#define TERMINAL_PUTC(c) putchar(c)
void TFC_InitTerminal(void);
void TFC_ProcessTerminal(void);
#endif
