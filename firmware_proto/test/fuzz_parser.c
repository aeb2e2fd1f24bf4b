/* Fuzz target: any bytes into the link parser and the whole device core.
 *
 * Built with clang's libFuzzer (make fuzz), or driven by test/fuzz_stream.c where libFuzzer
 * is missing. Beyond the sanitizers, it aborts if an invariant breaks:
 *   - without an accepted ARM or HOME frame, outputs stay off and nothing moves;
 *   - commanded positions stay within the soft limits, the state is a lifecycle state;
 *   - every frame the device sends parses back as a valid frame.
 */
#include <stdlib.h>
#include <string.h>

#include "device.h"

static int motion_allowed_by_frame;

static int emit(void *ctx, const uint8_t *wire, size_t n)
{
    uint8_t frame[LINK_MAX_ENCODED];
    link_frame_t f;
    size_t m;
    (void)ctx;
    if (n < 2 || n > LINK_MAX_ENCODED + 1 || wire[n - 1] != 0)
        abort();
    m = link_cobs_decode(wire, n - 1, frame);
    if (m == SIZE_MAX || link_parse(frame, m, &f) != RX_FRAME)
        abort();
    return 1;
}

static void observe(void *ctx, const link_frame_t *f)
{
    (void)ctx;
    if (f->type == LINK_ARM || f->type == LINK_HOME)
        motion_allowed_by_frame = 1;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static device_t d;
    static uint8_t scratch[4096];
    device_inputs_t in;
    link_frame_t f;
    uint32_t now = 1000;
    uint8_t i, mode;
    size_t at;
    if (size < 1)
        return 0;
    mode = data[0];
    link_parse(data + 1, size - 1, &f); /* the input as one frame */
    if (size - 1 <= sizeof scratch)
        link_cobs_decode(data + 1, size - 1, scratch); /* and as one COBS packet */
    memset(&in, 0, sizeof in);
    in.estop_input = (uint8_t)((mode & 0x30u) == 0x30u);
    in.has_feedback = (uint8_t)((mode >> 6) & 1u);
    motion_allowed_by_frame = 0;
    device_init(&d, &PROFILES[mode % PROFILE_COUNT], 0, emit, observe, 0, now, 0);
    for (at = 1; at < size; at += 7) { /* as a stream, 7 bytes between control steps */
        device_receive(&d, data + at, size - at < 7 ? size - at : 7, now);
        now += (mode & 0x80u) ? 30u : d.profile->period_ms;
        for (i = 0; i < d.profile->actuators; i++)
            in.measured[i] = device_commanded(&d, i);
        device_step(&d, &in, now);
        if (d.state > ST_FAULT || d.state < ST_DISARMED)
            abort();
        for (i = 0; i < d.profile->actuators; i++) {
            if (d.axis[i].pos < d.limits[i].min || d.axis[i].pos > d.limits[i].max)
                abort();
            if (!motion_allowed_by_frame && (d.outputs_on || d.axis[i].pos != (float)d.profile->actuator.park))
                abort();
        }
    }
    return 0;
}
