/* The main loop; see fw.h. */
#include "fw.h"

#include "hal.h"

static int emit(void *ctx, const uint8_t *bytes, size_t n)
{
    (void)ctx;
    return hal_serial_write(bytes, n);
}

void fw_init(fw_t *fw, const profile_t *profile, const char *name, device_observe_fn observe, void *ctx)
{
    int16_t start[LINK_MAX_ACTUATORS];
    int measured = hal_read_feedback(start, profile->actuators);
    uint32_t now = hal_millis();
    device_init(&fw->device, profile, name, emit, observe, ctx, now, measured ? start : 0);
    hal_write_outputs(&fw->device);
    fw->next_step_ms = now + profile->period_ms;
}

int fw_poll(fw_t *fw)
{
    device_t *d = &fw->device;
    uint8_t buf[64];
    device_inputs_t in;
    uint32_t now;
    size_t n;
    uint8_t was_on = d->outputs_on, chunks = 0;
    /* at most 256 bytes a call: a host that floods the link cannot starve the control step */
    while (chunks++ < 4 && (n = hal_serial_read(buf, sizeof buf)) > 0)
        device_receive(d, buf, n, hal_millis());
    if (hal_estop_input() && d->state != ST_ESTOP) /* latch at once, not at the next step */
        device_estop(d, F_ESTOP_INPUT);
    if (was_on && !d->outputs_on) /* an e-stop frame or input: outputs off now */
        hal_write_outputs(d);
    now = hal_millis();
    if ((int32_t)(now - fw->next_step_ms) < 0)
        return 0;
    in.estop_input = (uint8_t)hal_estop_input();
    in.has_feedback = (uint8_t)hal_read_feedback(in.measured, d->profile->actuators);
    device_step(d, &in, now);
    hal_write_outputs(d);
    fw->next_step_ms += d->profile->period_ms;
    if ((int32_t)(now - fw->next_step_ms) >= 0) /* late by a period or more: do not bunch steps */
        fw->next_step_ms = now + d->profile->period_ms;
    return 1;
}

uint32_t fw_ms_until_step(const fw_t *fw)
{
    int32_t left = (int32_t)(fw->next_step_ms - hal_millis());
    return left > 0 ? (uint32_t)left : 0u;
}
