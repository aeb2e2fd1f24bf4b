/* The hardware behind the core: what a board shim (board/mega2560.c) or the host build
 * (host/host_main.c) provides. Kept small on purpose: a clock, a byte pipe, one input,
 * optional feedback, the outputs. */
#ifndef HAL_H
#define HAL_H

#include <stddef.h>
#include <stdint.h>

#include "device.h"

uint32_t hal_millis(void);                             /* monotonic ms, wraps at 2^32 */
size_t hal_serial_read(uint8_t *buf, size_t cap);      /* what has arrived, never blocks */
int hal_serial_write(const uint8_t *bytes, size_t n);  /* queue a whole frame: 1, or 0 and drop it */
int hal_estop_input(void);                             /* 1: e-stop active (NC contact open, wire cut) */
int hal_read_feedback(int16_t *measured, uint8_t n);   /* 1 if the positions were measured */
/* Drive the outputs from d->axis[i].pos (counts) if d->outputs_on, else disable them. */
void hal_write_outputs(const device_t *d);

#endif
