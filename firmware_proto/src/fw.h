/* The firmware's main loop, shared by every board and the host build: HAL <-> device core. */
#ifndef FW_H
#define FW_H

#include "device.h"

typedef struct {
    device_t device;
    uint32_t next_step_ms;
} fw_t;

/* Boot: device DISARMED with outputs off (written to the HAL at once). */
void fw_init(fw_t *fw, const profile_t *profile, const char *name, device_observe_fn observe, void *ctx);
/* Call as often as possible: feeds received bytes, runs the control step when due.
 * Returns 1 if a control step ran. */
int fw_poll(fw_t *fw);
/* Milliseconds until the next control step is due (0: now). */
uint32_t fw_ms_until_step(const fw_t *fw);

#endif
