/* The device core, the control step: e-stop input, dead-man, noisy-link gate, following
 * error, homing, soft start, running, parking. Frames in and out: device_frames.c. */
#include "device_internal.h"

#include <string.h>

static const char *const STATE_NAMES[] = {"disconnected", "connecting", "disarmed", "homing", "soft_start",
                                          "running",      "parking",    "parked",   "estop",  "fault"};

const char *device_state_name(uint8_t state) { return state <= ST_FAULT ? STATE_NAMES[state] : "?"; }

int device_moving(uint8_t s) { return s == ST_HOMING || s == ST_SOFT_START || s == ST_RUNNING || s == ST_PARKING; }
int device_latched(uint8_t s) { return s == ST_ESTOP || s == ST_FAULT; }
static float dt_s(const device_t *d) { return (float)d->profile->period_ms * 0.001f; }
void device_count(device_t *d, link_counter_t c) { d->counters[c]++; }

int16_t device_commanded(const device_t *d, uint8_t i)
{
    float p = d->axis[i].pos;
    return (int16_t)(p >= 0.0f ? p + 0.5f : p - 0.5f);
}

void device_enter(device_t *d, uint8_t state)
{
    d->state = state;
    d->state_since_ms = d->now_ms;
    d->telemetry_now = 1;
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
        device_enter(d, ST_ESTOP);
}

static void fault_now(device_t *d, uint16_t fault_bit) /* when parking cannot be trusted */
{
    d->faults |= fault_bit | d->pending_faults;
    d->pending_faults = 0;
    d->outputs_on = 0;
    device_enter(d, ST_FAULT);
}

void device_park(device_t *d)
{
    if (d->state != ST_PARKING) {
        d->parks++;
        device_enter(d, ST_PARKING);
    }
}

void device_start_motion(device_t *d, uint8_t state)
{
    uint8_t i;
    d->outputs_on = 1;
    d->has_target = 0;
    for (i = 0; i < d->profile->actuators; i++) {
        if (d->has_feedback)
            d->axis[i].pos = (float)d->measured[i];
        d->axis[i].vel = 0.0f;
    }
    device_enter(d, state);
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
        device_count(d, C_LIMITED);
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
        device_enter(d, ST_RUNNING);
}

static void finish_park(device_t *d)
{
    d->outputs_on = 0;
    if (d->pending_faults) {
        d->faults |= d->pending_faults;
        d->pending_faults = 0;
        device_enter(d, ST_FAULT);
    } else {
        device_enter(d, ST_PARKED);
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
            device_park(d);
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
        device_count(d, C_DEADMAN);
        d->pending_faults |= F_LINK_TIMEOUT;
        device_park(d);
    }
    d->link_errors -= p->error_leak_per_s * dt_s(d);
    if (d->link_errors < 0.0f)
        d->link_errors = 0.0f;
    if (d->outputs_on && d->link_errors > p->error_budget && !(d->pending_faults & F_LINK_ERRORS)) {
        d->pending_faults |= F_LINK_ERRORS; /* each rejected packet risks an undetected one: stop */
        device_park(d);
    }
    if (d->outputs_on && d->has_feedback)
        check_following(d);
    d->limited = 0;
    switch (d->state) {
    case ST_HOMING:
        if (step_axes(d, 0, (float)p->actuator.home, p->homing_scale)) {
            d->homed = 1;
            if (d->arm_after_homing)
                device_start_motion(d, ST_SOFT_START);
            else
                device_park(d);
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
    case ST_PARKING: /* motion advances per step; the bound is in time (a loop starved of steps) */
        if (step_axes(d, 0, (float)p->actuator.park, p->park_scale))
            finish_park(d);
        else if (now_ms - d->state_since_ms >= PARK_BOUND_MS)
            fault_now(d, F_PARK_TIMEOUT);
        break;
    default:
        break;
    }
    if (d->telemetry_now ||
        (d->link_seen && now_ms - d->last_rx_ms < d->heartbeat_ms && now_ms - d->last_telemetry_ms >= d->telemetry_ms))
        device_send_telemetry(d);
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
