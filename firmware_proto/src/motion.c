/* Trajectory limiter: see motion.h. */
#include "motion.h"

#include <math.h>

static float clampf(float v, float lo, float hi) { return v < lo ? lo : (v > hi ? hi : v); }

/* 1 / (q + 1) for the usual q: a multiplication instead of a soft-float division on an AVR. */
static const float RECIPROCAL[16] = {1.0f,       0.5f,       1.0f / 3.0f,  0.25f,       0.2f,        1.0f / 6.0f,
                                     1.0f / 7.0f, 0.125f,     1.0f / 9.0f,  0.1f,        1.0f / 11.0f, 1.0f / 12.0f,
                                     1.0f / 13.0f, 1.0f / 14.0f, 1.0f / 15.0f, 0.0625f};

uint8_t axis_step(axis_t *axis, float target, const axis_limits_t *lim, float vscale, float dt)
{
    uint8_t acted = 0;
    float goal = clampf(target, lim->min, lim->max);
    float error, distance, a_dt, braking, q, v_stop, v_cap, v_want, dv, previous;
    if (goal != target)
        acted |= LIM_SOFT;
    error = goal - axis->pos;
    distance = fabsf(error);
    a_dt = lim->amax * dt;
    /* The fastest speed that can still stop within distance when the speed drops by a_dt a
     * period (what this loop does): with D = distance / (a_dt dt) and q whole periods of
     * braking after this one, (q + 1)(q / 2 + m - q) <= D gives m = q / 2 + D / (q + 1). */
    braking = distance / (a_dt * dt);
    q = floorf((sqrtf(1.0f + 8.0f * braking) - 1.0f) * 0.5f);
    v_stop = a_dt * (0.5f * q + (q < 16.0f ? braking * RECIPROCAL[(int)q] : braking / (q + 1.0f)));
    v_cap = lim->vmax * vscale;
    v_want = v_stop < v_cap ? v_stop : v_cap;
    if (v_cap <= v_stop && distance > 0.0f && fabsf(axis->vel) >= v_cap * 0.999f)
        acted |= LIM_VELOCITY;
    if (error < 0.0f)
        v_want = -v_want;
    dv = v_want - axis->vel;
    if (dv > a_dt || dv < -a_dt) {
        dv = clampf(dv, -a_dt, a_dt);
        acted |= LIM_ACCELERATION;
    }
    axis->vel += dv;
    previous = axis->pos;
    axis->pos += axis->vel * dt;
    if (fabsf(goal - axis->pos) < 0.01f && fabsf(axis->vel) + fabsf(dv) <= a_dt) { /* arrived: snap */
        axis->pos = goal;
        axis->vel = 0.0f;
    }
    /* Last guard: never further past a limit. An axis that starts outside (moved by hand while
     * the outputs were off) is held, not snapped, until it moves back in. */
    if ((axis->pos > lim->max && axis->vel > 0.0f) || (axis->pos < lim->min && axis->vel < 0.0f)) {
        axis->pos = previous > lim->max || previous < lim->min ? previous : clampf(axis->pos, lim->min, lim->max);
        axis->vel = 0.0f;
        acted |= LIM_SOFT;
    }
    return acted;
}

int axis_settled(const axis_t *axis, float where, float tolerance, const axis_limits_t *lim, float dt)
{
    return fabsf(axis->pos - where) <= tolerance && fabsf(axis->vel) <= lim->amax * dt;
}
