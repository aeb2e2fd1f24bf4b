/* Actuator profiles: hardware facts as data. One profile is chosen by config (the host
 * build's --profile, the board's PROFILE make variable); CONFIG frames may only tighten it.
 *
 * To add a profile: add a row to PROFILES in profile.c (and its id to link_vocab.Profile in
 * riderlive/platform/link_vocab.py and docs/platform-link.md).
 */
#ifndef PROFILE_H
#define PROFILE_H

#include <stdint.h>

typedef struct {
    int16_t soft_min, soft_max; /* widest soft limits, counts (CONFIG may narrow them) */
    int16_t home, park;         /* poses, counts */
    float vmax, amax;           /* widest velocity (counts/s) and acceleration (counts/s^2) limits */
    float vmin, amin;           /* slowest CONFIG may set: a park ends within PARK_BOUND_MS (below) */
    int16_t out_lo, out_hi;     /* counts at the two ends of the output range ... */
    uint16_t pulse_lo_us, pulse_hi_us; /* ... and the pulse widths there (hobby servo / RC input) */
} actuator_spec_t;

/* The longest a park may take, ms, from its first step to outputs off, for any accepted
 * CONFIG: from anywhere in the output range, moving at full speed the wrong way, at
 * park_scale of the slowest speed limit and the lowest acceleration limit CONFIG accepts
 * (vmin, amin). With D the farthest park distance, v the speed and a the acceleration
 * limit: D / (park_scale v) + park_scale v / a + v / a <= 4.8 s at every corner of
 * [vmin, vmax] x [amin, amax]; test_device checks it on the core itself
 * (docs/platform-link.md). Feedback that never arrives is bounded by the following error. */
#define PARK_BOUND_MS 5000u

typedef struct {
    const char *name;          /* also the default device name ARM must give */
    uint8_t id;                /* link_vocab.Profile */
    uint8_t actuators;         /* <= LINK_MAX_ACTUATORS */
    uint8_t needs_homing;      /* home before the first arm after boot or reset */
    uint8_t feedback;          /* the actuators report their positions (pots, encoders) */
    uint8_t period_ms;         /* control period */
    uint16_t heartbeat_ms;     /* dead-man timeout (CONFIG: 20 .. heartbeat_max_ms) */
    uint16_t heartbeat_max_ms;
    uint16_t telemetry_ms;     /* telemetry period while the link is alive */
    uint16_t pwm_hz;           /* pulse rate (CONFIG: 50 .. 330) */
    float soft_start_scale; /* soft start lasts distance / (scale vmax), within 1-5 s */
    float park_scale, homing_scale; /* speed caps, fractions of vmax */
    uint16_t homing_timeout_ms;
    int16_t settle_counts;     /* "arrived" tolerance */
    int16_t follow_counts;     /* following error tolerance (with feedback) ... */
    uint16_t follow_ms;        /* ... held this long -> fault */
    float error_budget;        /* rejected packets a moving device tolerates ... */
    float error_leak_per_s;    /* ... forgetting this many a second (a leaky bucket) */
    actuator_spec_t actuator;  /* every actuator of the profile */
} profile_t;

extern const profile_t PROFILES[];
extern const uint8_t PROFILE_COUNT;

/* The profile called name, or 0. */
const profile_t *profile_find(const char *name);

/* Output pulse width in microseconds for a commanded position (linear map, clamped). */
uint16_t profile_pulse_us(const profile_t *profile, float counts);

#endif
