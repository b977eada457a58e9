#ifndef TFC_TYPES_H_
#define TFC_TYPES_H_
#include <stdint.h>
#endif
