/* The device core's test harness, shared by test_device.c and test_config_bounds.c: one
 * device, a fake clock and perfect (or stuck) actuators; frames built with the link encoder,
 * the device's STATUS and TELEMETRY decoded. */
#ifndef DEVICE_HARNESS_H
#define DEVICE_HARNESS_H

#include <stdint.h>
#include <string.h>

#include "check.h"
#include "device.h"

static device_t d;
static device_inputs_t in;
static uint32_t now;
static uint16_t seq;
static int stuck = -1; /* an actuator that does not follow */
static struct {
    int statuses, telemetry;
    link_status_t last; /* the last STATUS */
} out;

static inline int emit(void *ctx, const uint8_t *wire, size_t n)
{
    uint8_t frame[LINK_MAX_ENCODED];
    size_t m = link_cobs_decode(wire, n - 1, frame);
    (void)ctx;
    CHECK(m != SIZE_MAX && wire[n - 1] == 0);
    if (frame[1] == LINK_STATUS) {
        out.statuses++;
        out.last.ack_seq = (uint16_t)(frame[4] | frame[5] << 8);
        out.last.ack_type = frame[6];
        out.last.result = frame[7];
        out.last.state = frame[8];
        out.last.faults = (uint16_t)(frame[9] | frame[10] << 8);
    } else if (frame[1] == LINK_TELEMETRY) {
        out.telemetry++;
    }
    return 1;
}

static inline void boot(const char *profile)
{
    memset(&in, 0, sizeof in);
    memset(&out, 0, sizeof out);
    now = 1000;
    seq = 100;
    stuck = -1;
    device_init(&d, profile_find(profile), 0, emit, 0, 0, now, 0);
}

static inline void send_raw(uint8_t type, uint16_t s, const uint8_t *body, size_t len)
{
    uint8_t wire[LINK_MAX_ENCODED + 1];
    size_t n = link_encode(type, s, body, len, wire);
    device_receive(&d, wire, n, now);
}

static inline void send(uint8_t type) { send_raw(type, seq++, 0, 0); }

static inline int command(uint8_t type) /* the STATUS result */
{
    int before = out.statuses;
    send(type);
    CHECK_EQ(out.statuses, before + 1);
    return out.last.result;
}

static inline int named(uint8_t type, const char *name)
{
    uint8_t body[1 + LINK_MAX_NAME];
    body[0] = (uint8_t)strlen(name);
    memcpy(body + 1, name, body[0]);
    send_raw(type, seq++, body, 1u + body[0]);
    return out.last.result;
}

static inline int config(uint8_t key, uint8_t index, int32_t value)
{
    uint8_t body[6] = {key, index};
    link_put_u32(body + 2, (uint32_t)value);
    send_raw(LINK_CONFIG, seq++, body, sizeof body);
    return out.last.result;
}

static inline void target_all(int16_t value)
{
    uint8_t body[1 + 2 * LINK_MAX_ACTUATORS], *p = body + 1, i;
    body[0] = d.profile->actuators;
    for (i = 0; i < body[0]; i++)
        p = link_put_u16(p, (uint16_t)value);
    send_raw(LINK_TARGET, seq++, body, (size_t)(p - body));
}

static inline void step(void)
{
    uint8_t i;
    now += d.profile->period_ms;
    for (i = 0; i < d.profile->actuators; i++)
        if ((int)i != stuck)
            in.measured[i] = device_commanded(&d, i);
    device_step(&d, &in, now);
}

static inline void run_ms(uint32_t ms, int16_t stream_target) /* steps, streaming targets (or heartbeats) */
{
    uint32_t end = now + ms;
    while (now < end) {
        if (stream_target != INT16_MIN)
            target_all(stream_target);
        else
            send(LINK_HEARTBEAT);
        step();
    }
}

#define NO_TARGET INT16_MIN

#endif
