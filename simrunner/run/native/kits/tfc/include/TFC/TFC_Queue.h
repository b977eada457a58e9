/* TFC_Queue.h (simulator): the serial queues print to the program's standard output. */
#ifndef TFC_QUEUE_H_
#define TFC_QUEUE_H_
#include <stdint.h>
typedef struct { uint16_t ReadPtr, WritePtr, QueueSize; uint8_t *QueueStorage; } ByteQueue;
extern ByteQueue SDA_SERIAL_OUTGOING_QUEUE;
extern ByteQueue SDA_SERIAL_INCOMING_QUEUE;
void InitByteQueue(ByteQueue *BQ, uint16_t Size, uint8_t *Storage);
uint16_t BytesInQueue(ByteQueue *BQ);
int16_t ByteEnqueue(ByteQueue *BQ, uint8_t Val);
int16_t ByteDequeue(ByteQueue *BQ, uint8_t *Val);
uint32_t Qprintf(ByteQueue *BQ, const char *FormatString, ...);
#endif
