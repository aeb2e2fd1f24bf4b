/* CONFIG's speed and acceleration floors bound the dead-man park: for every profile, at
 * every corner of [vmin, vmax] x [amin, amax] (the slowest and fastest configurations the
 * device accepts), from the far soft limit at rest and from full speed toward it, the park
 * ends (outputs off) within PARK_BOUND_MS of its first step. Simulated on the core itself
 * (perfect actuators, feedback where the profile has it). Prints the worst park per profile.
 */
#include <math.h>
#include <stdlib.h>

#include "check.h"
#include "device.h"
#include "device_harness.h"

enum { AT_REST, MOVING };

/* Arm under (v, a), run to the far limit (AT_REST) or cut the link at full speed toward it
 * (MOVING, dead-man 20 ms); returns the ms from the first park step to outputs off. */
static uint32_t park_ms(const char *profile, float v, float a, int how)
{
    const actuator_spec_t *spec;
    int16_t far;
    uint32_t t0, parking_at = 0;
    uint8_t i;
    boot(profile);
    spec = &d.profile->actuator;
    far = (int16_t)(spec->soft_max - spec->park > spec->park - spec->soft_min ? spec->soft_max : spec->soft_min);
    in.has_feedback = d.profile->feedback;
    send(LINK_HELLO);
    CHECK_EQ(config(K_HEARTBEAT_TIMEOUT_MS, 0, how == MOVING ? 20 : 1000), REASON_OK);
    for (i = 0; i < d.profile->actuators; i++) {
        CHECK_EQ(config(K_VELOCITY_LIMIT, i, (int32_t)v), REASON_OK);
        CHECK_EQ(config(K_ACCELERATION_LIMIT, i, (int32_t)a), REASON_OK);
    }
    CHECK_EQ(named(LINK_ARM, d.name), REASON_OK);
    t0 = now;
    while (d.state != ST_RUNNING && now - t0 < 60000) /* homing (platforms), soft start */
        run_ms(d.profile->period_ms, d.state == ST_HOMING ? NO_TARGET : spec->park);
    CHECK_EQ(d.state, ST_RUNNING);
    t0 = now;
    while (now - t0 < 60000) { /* toward the far limit: until there at rest, or at full speed */
        target_all(far);
        step();
        if (how == AT_REST ? device_commanded(&d, 0) == far && d.axis[0].vel == 0.0f
                           : fabsf(d.axis[0].vel) >= v * 0.999f)
            break;
    }
    t0 = now;
    while (d.outputs_on && now - t0 < 60000) { /* no more frames: the dead-man parks */
        step();
        if (!parking_at && d.state == ST_PARKING)
            parking_at = now;
    }
    CHECK_EQ(d.state, ST_FAULT);
    CHECK_EQ(d.faults, F_LINK_TIMEOUT);
    CHECK(abs(device_commanded(&d, 0) - spec->park) <= d.profile->settle_counts);
    return now - parking_at;
}

static void every_accepted_configuration_parks_within_the_bound(void)
{
    uint8_t p;
    for (p = 0; p < PROFILE_COUNT; p++) {
        const actuator_spec_t *spec = &PROFILES[p].actuator;
        const float vs[2] = {spec->vmin, spec->vmax}, as[2] = {spec->amin, spec->amax};
        uint32_t worst = 0, ms;
        int iv, ia, how;
        for (iv = 0; iv < 2; iv++)
            for (ia = 0; ia < 2; ia++)
                for (how = AT_REST; how <= MOVING; how++) {
                    ms = park_ms(PROFILES[p].name, vs[iv], as[ia], how);
                    CHECK(ms <= PARK_BOUND_MS);
                    worst = ms > worst ? ms : worst;
                }
        printf("test_config_bounds: %s: slowest park %u ms (vmin %.0f counts/s, amin %.0f counts/s^2; bound %u ms)\n",
               PROFILES[p].name, (unsigned)worst, (double)spec->vmin, (double)spec->amin, PARK_BOUND_MS);
    }
}

static void limits_at_their_edges(void) /* accepted at each edge, refused (counted) just beyond */
{
    uint8_t p;
    for (p = 0; p < PROFILE_COUNT; p++) {
        const actuator_spec_t *spec = &PROFILES[p].actuator;
        uint16_t refused;
        boot(PROFILES[p].name);
        send(LINK_HELLO);
        refused = d.counters[C_REFUSED];
        CHECK_EQ(config(K_VELOCITY_LIMIT, 0, (int32_t)spec->vmin - 1), REASON_OUT_OF_RANGE);
        CHECK_EQ(config(K_VELOCITY_LIMIT, 0, (int32_t)spec->vmax + 1), REASON_OUT_OF_RANGE);
        CHECK_EQ(config(K_ACCELERATION_LIMIT, 0, (int32_t)spec->amin - 1), REASON_OUT_OF_RANGE);
        CHECK_EQ(config(K_ACCELERATION_LIMIT, 0, (int32_t)spec->amax + 1), REASON_OUT_OF_RANGE);
        CHECK_EQ(config(K_VELOCITY_LIMIT, 0, INT32_MIN), REASON_OUT_OF_RANGE);
        CHECK_EQ(config(K_ACCELERATION_LIMIT, 0, INT32_MAX), REASON_OUT_OF_RANGE);
        CHECK_EQ(d.counters[C_REFUSED], refused + 6);
        CHECK_EQ(d.last_reason, REASON_OUT_OF_RANGE);
        CHECK(d.limits[0].vmax == spec->vmax && d.limits[0].amax == spec->amax); /* unchanged */
        CHECK_EQ(config(K_VELOCITY_LIMIT, 0, (int32_t)spec->vmin), REASON_OK);
        CHECK_EQ(config(K_ACCELERATION_LIMIT, 0, (int32_t)spec->amin), REASON_OK);
        CHECK(d.limits[0].vmax == spec->vmin && d.limits[0].amax == spec->amin);
        CHECK_EQ(config(K_VELOCITY_LIMIT, 0, (int32_t)spec->vmax), REASON_OK);
        CHECK_EQ(config(K_ACCELERATION_LIMIT, 0, (int32_t)spec->amax), REASON_OK);
        CHECK_EQ(d.counters[C_REFUSED], refused + 6);
    }
}

int main(void)
{
    every_accepted_configuration_parks_within_the_bound();
    limits_at_their_edges();
    return CHECK_DONE("test_config_bounds");
}
