/* The device core; see device.h and docs/platform-link.md. */
#include "device.h"

#include <string.h>

static const char *const STATE_NAMES[] = {"disconnected", "connecting", "disarmed", "homing", "soft_start",
                                          "running",      "parking",    "parked",   "estop",  "fault"};

const char *device_state_name(uint8_t state) { return state <= ST_FAULT ? STATE_NAMES[state] : "?"; }

static int moving(uint8_t s) { return s == ST_HOMING || s == ST_SOFT_START || s == ST_RUNNING || s == ST_PARKING; }
static int latched(uint8_t s) { return s == ST_ESTOP || s == ST_FAULT; }
static float dt_s(const device_t *d) { return (float)d->profile->period_ms * 0.001f; }
static void count(device_t *d, link_counter_t c) { d->counters[c]++; }

int16_t device_commanded(const device_t *d, uint8_t i)
{
    float p = d->axis[i].pos;
    return (int16_t)(p >= 0.0f ? p + 0.5f : p - 0.5f);
}

static void enter(device_t *d, uint8_t state)
{
    d->state = state;
    d->state_since_ms = d->now_ms;
    d->telemetry_now = 1;
}

static void sent(device_t *d, const uint8_t *wire, size_t n)
{
    d->tx_seq++;
    if (!d->emit || !d->emit(d->ctx, wire, n))
        count(d, C_TX_DROPPED);
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

static void send_telemetry(device_t *d)
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
        count(d, C_REFUSED);
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
    count(d, C_REFUSED);
    d->last_reason = reason;
}

void device_estop(device_t *d, uint16_t fault_bit)
{
    uint8_t i;
    d->faults |= fault_bit | d->pending_faults;
    d->pending_faults = 0;
    d->outputs_on = 0;
    for (i = 0; i < d->profile->actuators; i++)
        d->axis[i].vel = 0.0f;
    if (d->state != ST_ESTOP)
        enter(d, ST_ESTOP);
}

static void fault_now(device_t *d, uint16_t fault_bit) /* when parking cannot be trusted */
{
    d->faults |= fault_bit | d->pending_faults;
    d->pending_faults = 0;
    d->outputs_on = 0;
    enter(d, ST_FAULT);
}

static void park(device_t *d)
{
    if (d->state != ST_PARKING)
        enter(d, ST_PARKING);
}

static void start_motion(device_t *d, uint8_t state)
{
    uint8_t i;
    d->outputs_on = 1;
    d->has_target = 0;
    for (i = 0; i < d->profile->actuators; i++) {
        if (d->has_feedback)
            d->axis[i].pos = (float)d->measured[i];
        d->axis[i].vel = 0.0f;
    }
    enter(d, state);
}

/* ARM and HOME move hardware: only from rest, e-stop released, naming this device. */
static uint8_t motion_allowed(const device_t *d, const link_frame_t *f)
{
    if (latched(d->state))
        return REASON_LATCHED;
    if (moving(d->state))
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
    case K_SOFT_MIN:
        if (v < a->soft_min || (float)v >= lim->max) return REASON_OUT_OF_RANGE;
        lim->min = (float)v;
        return REASON_OK;
    case K_SOFT_MAX:
        if (v > a->soft_max || (float)v <= lim->min) return REASON_OUT_OF_RANGE;
        lim->max = (float)v;
        return REASON_OK;
    case K_VELOCITY_LIMIT:
        if (v <= 0 || (float)v > a->vmax) return REASON_OUT_OF_RANGE;
        lim->vmax = (float)v;
        return REASON_OK;
    case K_ACCELERATION_LIMIT:
        if (v <= 0 || (float)v > a->amax) return REASON_OUT_OF_RANGE;
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
        count(d, C_CLIPPED);
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
            start_motion(d, home_first ? ST_HOMING : ST_SOFT_START);
        }
        break;
    case LINK_HOME:
        r = motion_allowed(d, f);
        if (r == REASON_OK) {
            d->homed = 0;
            d->arm_after_homing = 0;
            start_motion(d, ST_HOMING);
        }
        break;
    case LINK_DISARM:
    case LINK_PARK:
        if (latched(s))
            r = REASON_LATCHED;
        else if (moving(s))
            park(d);
        else if (f->type == LINK_DISARM && s == ST_PARKED)
            enter(d, ST_DISARMED);
        break;
    case LINK_ESTOP:
        device_estop(d, F_ESTOP_LINK);
        break;
    case LINK_RESET:
        if (moving(s))
            r = REASON_MOVING;
        else if (latched(s) && d->estop_input)
            r = REASON_ESTOP_INPUT;
        else {
            if (latched(s) && d->profile->needs_homing)
                d->homed = 0; /* outputs were cut: positions are no longer trusted */
            d->faults = 0;
            d->pending_faults = 0;
            if (s != ST_DISARMED)
                enter(d, ST_DISARMED);
        }
        break;
    default: /* LINK_CONFIG */
        r = latched(s) ? REASON_LATCHED : (moving(s) ? REASON_MOVING : configure(d, f));
        break;
    }
    reply(d, f, r);
}

static void on_frame(device_t *d, const link_frame_t *f)
{
    uint16_t gap = 0;
    if (f->type >= LINK_HELLO_REPLY) { /* a device -> host frame: not for us */
        count(d, C_RX_TYPE);
        return;
    }
    if (f->type == LINK_HELLO)
        d->rx_seq.valid = 0; /* a session restarts the seq window */
    if (!link_seq_accept(&d->rx_seq, f->seq, &gap)) {
        count(d, C_RX_STALE);
        return;
    }
    d->counters[C_RX_GAP] = (uint16_t)(d->counters[C_RX_GAP] + gap);
    count(d, C_RX_OK);
    d->last_rx_ms = d->now_ms;
    d->link_seen = 1;
    if (d->observe)
        d->observe(d->ctx, f);
    if (f->type == LINK_HELLO) {
        if (moving(d->state))
            park(d); /* a new session never inherits motion */
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
            count(d, (link_counter_t)COUNTER_OF[r]);
            d->link_errors += 1.0f;
        }
    }
}

/* Step every axis toward goal (per axis) or toward one pose; 1 when all have settled there. */
static int step_axes(device_t *d, const float *goals, float pose, float vscale)
{
    uint8_t i, acted = 0;
    int settled = 1;
    float dt = dt_s(d), tol = (float)d->profile->settle_counts;
    for (i = 0; i < d->profile->actuators; i++) {
        float goal = goals ? goals[i] : pose;
        acted |= axis_step(&d->axis[i], goal, &d->limits[i], vscale, dt);
        settled &= axis_settled(&d->axis[i], goal, tol, &d->limits[i], dt);
        if (d->has_feedback && goals == 0) /* homing and parking also wait for the actuators */
            settled &= (d->measured[i] - goal) * (d->measured[i] - goal) <= 16.0f * tol * tol;
    }
    d->limited = (uint8_t)((acted & (LIM_VELOCITY | LIM_ACCELERATION)) != 0);
    if (d->limited && d->state == ST_RUNNING)
        count(d, C_LIMITED);
    return settled;
}

static float smoothstep(float x) { return x <= 0.0f ? 0.0f : (x >= 1.0f ? 1.0f : x * x * (3.0f - 2.0f * x)); }

static void soft_start(device_t *d)
{
    float goals[LINK_MAX_ACTUATORS] = {0}, far = 0.0f, s;
    uint32_t duration;
    uint8_t i, n = d->profile->actuators;
    if (!d->has_target) { /* hold until the first target */
        for (i = 0; i < n; i++)
            goals[i] = d->axis[i].pos;
        step_axes(d, goals, 0.0f, 1.0f);
        return;
    }
    for (i = 0; i < n; i++) {
        float gap = (float)d->target[i] - d->blend_from[i];
        gap = gap < 0.0f ? -gap : gap;
        far = gap > far ? gap : far;
    }
    /* 1-5 s: the farthest actuator at soft_start_scale of its speed limit */
    duration = (uint32_t)(1000.0f * far / (d->profile->soft_start_scale * d->profile->actuator.vmax));
    duration = duration < 1000u ? 1000u : (duration > 5000u ? 5000u : duration);
    s = smoothstep((float)(d->now_ms - d->state_since_ms) / (float)duration);
    for (i = 0; i < n; i++)
        goals[i] = d->blend_from[i] + s * ((float)d->target[i] - d->blend_from[i]);
    step_axes(d, goals, 0.0f, 1.0f);
    if (s >= 1.0f)
        enter(d, ST_RUNNING);
}

static void finish_park(device_t *d)
{
    d->outputs_on = 0;
    if (d->pending_faults) {
        d->faults |= d->pending_faults;
        d->pending_faults = 0;
        enter(d, ST_FAULT);
    } else {
        enter(d, ST_PARKED);
    }
}

static void check_following(device_t *d)
{
    uint8_t i, off = 0;
    for (i = 0; i < d->profile->actuators; i++) {
        float e = (float)d->measured[i] - d->axis[i].pos;
        if (e > d->profile->follow_counts || e < -d->profile->follow_counts)
            off = 1;
    }
    if (!off) {
        d->following = 0;
        return;
    }
    if (!d->following) {
        d->following = 1;
        d->follow_since_ms = d->now_ms;
    } else if (d->now_ms - d->follow_since_ms >= d->profile->follow_ms) {
        if (d->state == ST_PARKING || d->state == ST_HOMING) {
            fault_now(d, F_FOLLOWING_ERROR); /* cannot even park: outputs off */
        } else {
            d->pending_faults |= F_FOLLOWING_ERROR;
            park(d);
        }
        d->following = 0;
    }
}

void device_step(device_t *d, const device_inputs_t *in, uint32_t now_ms)
{
    const profile_t *p = d->profile;
    float goals[LINK_MAX_ACTUATORS] = {0};
    uint8_t i;
    d->now_ms = now_ms;
    d->estop_input = in->estop_input;
    d->has_feedback = in->has_feedback;
    if (in->has_feedback)
        memcpy(d->measured, in->measured, sizeof d->measured);
    if (in->estop_input)
        device_estop(d, F_ESTOP_INPUT);
    if (d->outputs_on && !(d->pending_faults & F_LINK_TIMEOUT) &&
        (!d->link_seen || now_ms - d->last_rx_ms >= d->heartbeat_ms)) { /* the dead-man */
        count(d, C_DEADMAN);
        d->pending_faults |= F_LINK_TIMEOUT;
        park(d);
    }
    d->link_errors -= p->error_leak_per_s * dt_s(d);
    if (d->link_errors < 0.0f)
        d->link_errors = 0.0f;
    if (d->outputs_on && d->link_errors > p->error_budget && !(d->pending_faults & F_LINK_ERRORS)) {
        d->pending_faults |= F_LINK_ERRORS; /* each rejected packet risks an undetected one: stop */
        park(d);
    }
    if (d->outputs_on && d->has_feedback)
        check_following(d);
    d->limited = 0;
    switch (d->state) {
    case ST_HOMING:
        if (step_axes(d, 0, (float)p->actuator.home, p->homing_scale)) {
            d->homed = 1;
            if (d->arm_after_homing)
                start_motion(d, ST_SOFT_START);
            else
                park(d);
        } else if (now_ms - d->state_since_ms >= p->homing_timeout_ms) {
            fault_now(d, F_HOMING_TIMEOUT);
        }
        break;
    case ST_SOFT_START:
        soft_start(d);
        break;
    case ST_RUNNING:
        for (i = 0; i < p->actuators; i++)
            goals[i] = (float)d->target[i];
        step_axes(d, goals, 0.0f, 1.0f);
        break;
    case ST_PARKING:
        if (step_axes(d, 0, (float)p->actuator.park, p->park_scale))
            finish_park(d);
        break;
    default:
        break;
    }
    if (d->telemetry_now ||
        (d->link_seen && now_ms - d->last_rx_ms < d->heartbeat_ms && now_ms - d->last_telemetry_ms >= d->telemetry_ms))
        send_telemetry(d);
}

void device_init(device_t *d, const profile_t *profile, const char *name, device_emit_fn emit,
                 device_observe_fn observe, void *ctx, uint32_t now_ms, const int16_t *start)
{
    const actuator_spec_t *a = &profile->actuator;
    uint8_t i;
    memset(d, 0, sizeof *d);
    d->profile = profile;
    strncpy(d->name, name ? name : profile->name, LINK_MAX_NAME);
    d->emit = emit;
    d->observe = observe;
    d->ctx = ctx;
    link_rx_init(&d->rx);
    d->heartbeat_ms = profile->heartbeat_ms;
    d->telemetry_ms = profile->telemetry_ms;
    d->pwm_hz = profile->pwm_hz;
    for (i = 0; i < profile->actuators; i++) {
        d->limits[i].min = (float)a->soft_min;
        d->limits[i].max = (float)a->soft_max;
        d->limits[i].vmax = a->vmax;
        d->limits[i].amax = a->amax;
        d->axis[i].pos = start ? (float)start[i] : (float)a->park;
        d->target[i] = a->park;
    }
    d->now_ms = d->state_since_ms = d->last_telemetry_ms = now_ms;
    d->state = ST_DISARMED;
}
