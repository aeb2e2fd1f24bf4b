/* The profiles; see profile.h. Positions in counts: 0.01 mm (linear) or 0.01 deg. */
#include "profile.h"

#include <string.h>

/* Timing shared by the profiles: 250 Hz control, 200 ms dead-man, 50 Hz telemetry; a moving
 * device parks when the link rejects more than 25 packets beyond 10 a second. */
#define COMMON_TIMING \
    .period_ms = 4, .heartbeat_ms = 200, .heartbeat_max_ms = 1000, .telemetry_ms = 20, \
    .soft_start_scale = 0.2f, .park_scale = 0.25f, .homing_scale = 0.2f, .homing_timeout_ms = 30000, \
    .settle_counts = 5, .follow_counts = 1000, .follow_ms = 200, .error_budget = 25.0f, .error_leak_per_s = 10.0f

/* 150 mm linear actuators with an RC/pulse position input (1000-2000 us = retracted-extended),
 * 250 mm/s, 5 m/s^2; parked fully down on the soft minimum, homed at mid stroke. CONFIG may
 * slow them to 130 mm/s and 1.25 m/s^2, no further: a park over the whole 145 mm at 25 %
 * of 130 mm/s takes 4.6 s (PARK_BOUND_MS). */
#define LINEAR_150MM \
    {.soft_min = 500, .soft_max = 14500, .home = 7500, .park = 500, .vmax = 25000.0f, .amax = 500000.0f, \
     .vmin = 13000.0f, .amin = 125000.0f, \
     .out_lo = 0, .out_hi = 15000, .pulse_lo_us = 1000, .pulse_hi_us = 2000}

const profile_t PROFILES[] = {
    /* A 6-DOF Stewart platform. */
    {.name = "platform6", .id = 1, .actuators = 6, .needs_homing = 1, .feedback = 1, .pwm_hz = 200, COMMON_TIMING,
     .actuator = LINEAR_150MM},
    /* The 3-DOF rig (heave, pitch, roll): the same actuators, three of them. */
    {.name = "platform3", .id = 2, .actuators = 3, .needs_homing = 1, .feedback = 1, .pwm_hz = 200, COMMON_TIMING,
     .actuator = LINEAR_150MM},
    /* Hobby PWM servos for a low-cost rider puppet: +-90 deg = 500-2500 us at 50 Hz (analog
     * servos; digital ones take up to 330 Hz by CONFIG), 300 deg/s. No feedback, no homing.
     * CONFIG may slow them to 80 deg/s and 750 deg/s^2: a park over 90 deg takes 4.6 s. */
    {.name = "servo8", .id = 3, .actuators = 8, .needs_homing = 0, .feedback = 0, .pwm_hz = 50, COMMON_TIMING,
     .actuator = {.soft_min = -8500, .soft_max = 8500, .home = 0, .park = 0, .vmax = 30000.0f,
                  .amax = 300000.0f, .vmin = 8000.0f, .amin = 75000.0f, .out_lo = -9000, .out_hi = 9000,
                  .pulse_lo_us = 500, .pulse_hi_us = 2500}},
};
const uint8_t PROFILE_COUNT = (uint8_t)(sizeof PROFILES / sizeof PROFILES[0]);

const profile_t *profile_find(const char *name)
{
    uint8_t i;
    for (i = 0; i < PROFILE_COUNT; i++)
        if (strcmp(PROFILES[i].name, name) == 0)
            return &PROFILES[i];
    return 0;
}

uint16_t profile_pulse_us(const profile_t *profile, float counts)
{
    const actuator_spec_t *a = &profile->actuator;
    float f = (counts - (float)a->out_lo) / ((float)a->out_hi - (float)a->out_lo);
    f = f < 0.0f ? 0.0f : (f > 1.0f ? 1.0f : f);
    return (uint16_t)((float)a->pulse_lo_us + f * (float)(a->pulse_hi_us - a->pulse_lo_us) + 0.5f);
}
