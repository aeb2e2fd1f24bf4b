/* The device core's internals, shared by device.c (the control step) and device_frames.c
 * (frames in and out). Not an API: boards and the host build use device.h. */
#ifndef DEVICE_INTERNAL_H
#define DEVICE_INTERNAL_H

#include "device.h"

int device_moving(uint8_t state);  /* homing, soft_start, running, parking: outputs on */
int device_latched(uint8_t state); /* estop, fault */
void device_count(device_t *d, link_counter_t c);
void device_enter(device_t *d, uint8_t state);       /* and send TELEMETRY at the next step */
void device_park(device_t *d);                       /* begin an eased park (once) */
void device_start_motion(device_t *d, uint8_t state); /* outputs on, from where the actuators are */
void device_send_telemetry(device_t *d);

#endif
