/* The device core, frames in and out: the seq window, commands in every state, CONFIG,
 * STATUS, HELLO_REPLY and TELEMETRY. See device.h and docs/platform-link.md. */
#include <string.h>

#include "device_internal.h"

static void sent(device_t *d, const uint8_t *wire, size_t n)
{
    d->tx_seq++;
    if (!d->emit || !d->emit(d->ctx, wire, n))
        device_count(d, C_TX_DROPPED);
}

static void send_hello_reply(device_t *d)
{
    uint8_t wire[LINK_MAX_ENCODED + 1];
    link_hello_reply_t m;
    m.fw_major = FW_VERSION_MAJOR;
    m.fw_minor = FW_VERSION_MINOR;
    m.profile = d->profile->id;
    m.actuators = d->profile->actuators;
    m.period_us = (uint16_t)(d->profile->period_ms * 1000u);
    m.heartbeat_ms = d->heartbeat_ms;
    m.device = d->name;
    sent(d, wire, link_encode_hello_reply(d->tx_seq, &m, wire));
}

void device_send_telemetry(device_t *d)
{
    uint8_t wire[LINK_MAX_ENCODED + 1];
    link_telemetry_t m;
    uint8_t i;
    int link_ok = d->link_seen && d->now_ms - d->last_rx_ms < d->heartbeat_ms;
    m.state = d->state;
    m.flags = (uint8_t)((d->homed ? FL_HOMED : 0) | (d->estop_input ? FL_ESTOP_INPUT : 0) |
                        (d->outputs_on ? FL_OUTPUTS_ON : 0) | (link_ok ? FL_LINK_OK : 0) |
                        (d->limited ? FL_LIMITED : 0));
    m.faults = d->faults;
    m.uptime_ms = d->now_ms;
    m.last_reason = d->last_reason;
    m.count = d->profile->actuators;
    for (i = 0; i < m.count; i++) {
        m.commanded[i] = device_commanded(d, i);
        m.measured[i] = d->has_feedback ? d->measured[i] : m.commanded[i];
    }
    memcpy(m.counters, d->counters, sizeof m.counters);
    sent(d, wire, link_encode_telemetry(d->tx_seq, &m, wire));
    d->last_telemetry_ms = d->now_ms;
    d->telemetry_now = 0;
}

static void reply(device_t *d, const link_frame_t *f, uint8_t result)
{
    uint8_t wire[LINK_MAX_ENCODED + 1];
    link_status_t m;
    if (result != REASON_OK) {
        device_count(d, C_REFUSED);
        d->last_reason = result;
    }
    m.ack_seq = f->seq;
    m.ack_type = f->type;
    m.result = result;
    m.state = d->state;
    m.faults = d->faults;
    sent(d, wire, link_encode_status(d->tx_seq, &m, wire));
}

static void refuse_quietly(device_t *d, uint8_t reason) /* TARGET: no STATUS, counted */
{
    device_count(d, C_REFUSED);
    d->last_reason = reason;
}

/* ARM and HOME move hardware: only from rest, e-stop released, naming this device. */
static uint8_t motion_allowed(const device_t *d, const link_frame_t *f)
{
    if (device_latched(d->state))
        return REASON_LATCHED;
    if (device_moving(d->state))
        return REASON_MOVING;
    if (d->estop_input)
        return REASON_ESTOP_INPUT;
    if (strcmp(f->name, d->name) != 0)
        return REASON_WRONG_DEVICE;
    return REASON_OK;
}

static uint8_t configure(device_t *d, const link_frame_t *f)
{
    const actuator_spec_t *a = &d->profile->actuator;
    axis_limits_t *lim;
    int32_t v = f->value;
    int per_actuator = f->key >= K_SOFT_MIN && f->key <= K_ACCELERATION_LIMIT;
    if (per_actuator ? f->index >= d->profile->actuators : f->index != 0)
        return REASON_UNKNOWN_KEY;
    lim = &d->limits[f->index < LINK_MAX_ACTUATORS ? f->index : 0];
    switch (f->key) {
    case K_HEARTBEAT_TIMEOUT_MS:
        if (v < 20 || v > d->profile->heartbeat_max_ms) return REASON_OUT_OF_RANGE;
        d->heartbeat_ms = (uint16_t)v;
        return REASON_OK;
    case K_TELEMETRY_PERIOD_MS:
        if (v < d->profile->period_ms || v > 1000) return REASON_OUT_OF_RANGE;
        d->telemetry_ms = (uint16_t)v;
        return REASON_OK;
    case K_SOFT_MIN: /* the park and home poses stay inside: parking must always arrive */
        if (v < a->soft_min || (float)v >= lim->max || v > a->park || v > a->home) return REASON_OUT_OF_RANGE;
        lim->min = (float)v;
        return REASON_OK;
    case K_SOFT_MAX:
        if (v > a->soft_max || (float)v <= lim->min || v < a->park || v < a->home) return REASON_OUT_OF_RANGE;
        lim->max = (float)v;
        return REASON_OK;
    case K_VELOCITY_LIMIT: /* never so slow that a park outlasts PARK_BOUND_MS */
        if ((float)v < a->vmin || (float)v > a->vmax) return REASON_OUT_OF_RANGE;
        lim->vmax = (float)v;
        return REASON_OK;
    case K_ACCELERATION_LIMIT:
        if ((float)v < a->amin || (float)v > a->amax) return REASON_OUT_OF_RANGE;
        lim->amax = (float)v;
        return REASON_OK;
    case K_PWM_HZ:
        if (v < 50 || v > 330) return REASON_OUT_OF_RANGE;
        d->pwm_hz = (uint16_t)v;
        return REASON_OK;
    default:
        return REASON_UNKNOWN_KEY;
    }
}

static void on_target(device_t *d, const link_frame_t *f)
{
    uint8_t i, clipped = 0;
    if (d->state != ST_SOFT_START && d->state != ST_RUNNING) {
        refuse_quietly(d, REASON_NOT_ARMED);
        return;
    }
    if (f->count != d->profile->actuators) {
        refuse_quietly(d, REASON_BAD_COUNT);
        return;
    }
    for (i = 0; i < f->count; i++) {
        int16_t v = f->positions[i];
        if ((float)v < d->limits[i].min) { v = (int16_t)d->limits[i].min; clipped = 1; }
        if ((float)v > d->limits[i].max) { v = (int16_t)d->limits[i].max; clipped = 1; }
        d->target[i] = v;
    }
    if (clipped)
        device_count(d, C_CLIPPED);
    if (!d->has_target && d->state == ST_SOFT_START) { /* the soft start blends from here */
        for (i = 0; i < f->count; i++)
            d->blend_from[i] = d->axis[i].pos;
        d->state_since_ms = d->now_ms;
    }
    d->has_target = 1;
}

static void on_command(device_t *d, const link_frame_t *f)
{
    uint8_t r = REASON_OK, s = d->state;
    switch (f->type) {
    case LINK_ARM:
        r = motion_allowed(d, f);
        if (r == REASON_OK) {
            int home_first = d->profile->needs_homing && !d->homed;
            d->arm_after_homing = (uint8_t)home_first;
            device_start_motion(d, home_first ? ST_HOMING : ST_SOFT_START);
        }
        break;
    case LINK_HOME:
        r = motion_allowed(d, f);
        if (r == REASON_OK) {
            d->homed = 0;
            d->arm_after_homing = 0;
            device_start_motion(d, ST_HOMING);
        }
        break;
    case LINK_DISARM:
    case LINK_PARK:
        if (device_latched(s))
            r = REASON_LATCHED;
        else if (device_moving(s))
            device_park(d);
        else if (f->type == LINK_DISARM && s == ST_PARKED)
            device_enter(d, ST_DISARMED);
        break;
    case LINK_ESTOP:
        device_estop(d, F_ESTOP_LINK);
        break;
    case LINK_RESET:
        if (device_moving(s))
            r = REASON_MOVING;
        else if (device_latched(s) && d->estop_input)
            r = REASON_ESTOP_INPUT;
        else {
            if (device_latched(s) && d->profile->needs_homing)
                d->homed = 0; /* outputs were cut: positions are no longer trusted */
            d->faults = 0;
            d->pending_faults = 0;
            if (s != ST_DISARMED)
                device_enter(d, ST_DISARMED);
        }
        break;
    default: /* LINK_CONFIG */
        r = device_latched(s) ? REASON_LATCHED : (device_moving(s) ? REASON_MOVING : configure(d, f));
        break;
    }
    reply(d, f, r);
}

static void on_frame(device_t *d, const link_frame_t *f)
{
    uint16_t gap = 0;
    if (f->type >= LINK_HELLO_REPLY) { /* a device -> host frame: not for us */
        device_count(d, C_RX_TYPE);
        return;
    }
    if (f->type == LINK_HELLO)
        d->rx_seq.valid = 0; /* a session restarts the seq window */
    if (!link_seq_accept(&d->rx_seq, f->seq, &gap)) {
        device_count(d, C_RX_STALE);
        return;
    }
    d->counters[C_RX_GAP] = (uint16_t)(d->counters[C_RX_GAP] + gap);
    device_count(d, C_RX_OK);
    d->last_rx_ms = d->now_ms;
    d->link_seen = 1;
    if (d->observe)
        d->observe(d->ctx, f);
    if (f->type == LINK_HELLO) {
        if (device_moving(d->state))
            device_park(d); /* a new session never inherits motion */
        send_hello_reply(d);
    } else if (f->type == LINK_TARGET) {
        on_target(d, f);
    } else if (f->type != LINK_HEARTBEAT) {
        on_command(d, f);
    }
}

void device_receive(device_t *d, const uint8_t *bytes, size_t n, uint32_t now_ms)
{
    static const uint8_t COUNTER_OF[] = {0, C_RX_OK, C_RX_COBS, C_RX_SHORT, C_RX_OVERSIZE,
                                         C_RX_CRC, C_RX_VERSION, C_RX_TYPE, C_RX_LENGTH};
    link_frame_t frame;
    d->now_ms = now_ms;
    while (n--) {
        link_rx_result_t r = link_rx_byte(&d->rx, *bytes++, &frame);
        if (r == RX_FRAME)
            on_frame(d, &frame);
        else if (r != RX_NONE) {
            device_count(d, (link_counter_t)COUNTER_OF[r]);
            d->link_errors += 1.0f;
        }
    }
}

