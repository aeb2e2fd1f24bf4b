/* The trajectory limiter: its limits hold for any target stream, and a step arrives in the
 * trapezoid's time without overshoot. */
#include <math.h>

#include "check.h"
#include "motion.h"

static uint32_t rng = 12345u;
static float uniform(float lo, float hi)
{
    rng = rng * 1664525u + 1013904223u;
    return lo + (hi - lo) * (float)(rng >> 8) / 16777216.0f;
}

static void limits_hold_for_random_targets(void)
{
    const axis_limits_t lim = {500.0f, 14500.0f, 25000.0f, 500000.0f};
    const float dt = 0.004f, eps = 1e-3f;
    axis_t a = {7500.0f, 0.0f};
    float worst_v = 0.0f, worst_dv = 0.0f, lo = 1e9f, hi = -1e9f;
    int k;
    for (k = 0; k < 200000; k++) {
        float target = k % 50 == 0 ? uniform(-40000.0f, 40000.0f) : (k % 7 == 0 ? uniform(0.0f, 15000.0f) : a.pos);
        float v0 = a.vel, scale = k % 1000 < 500 ? 1.0f : 0.25f;
        axis_step(&a, target, &lim, scale, dt);
        worst_v = fmaxf(worst_v, fabsf(a.vel) - lim.vmax * scale);
        worst_dv = fmaxf(worst_dv, fabsf(a.vel - v0) - lim.amax * dt);
        lo = fminf(lo, a.pos);
        hi = fmaxf(hi, a.pos);
    }
    CHECK(worst_v <= eps * lim.vmax);
    CHECK(worst_dv <= eps * lim.amax * dt);
    CHECK(lo >= lim.min && hi <= lim.max);
}

/* A 10 000-count step at 25 000 counts/s, 500 000 counts/s^2: accelerate 50 ms (625
 * counts), cruise, brake 50 ms: 0.45 s in all (hand-computed: d/v + v/a). */
static void step_arrives_on_time_without_overshoot(void)
{
    const axis_limits_t lim = {-20000.0f, 20000.0f, 25000.0f, 500000.0f};
    const float dt = 0.004f;
    axis_t a = {0.0f, 0.0f};
    float furthest = 0.0f;
    int k, arrived = -1;
    for (k = 0; k < 500; k++) {
        uint8_t acted = axis_step(&a, 10000.0f, &lim, 1.0f, dt);
        furthest = fmaxf(furthest, a.pos);
        if (k == 40) /* mid-way: cruising at the speed limit, and saying so */
            CHECK(fabsf(a.vel - 25000.0f) < 1.0f && (acted & LIM_VELOCITY));
        if (arrived < 0 && axis_settled(&a, 10000.0f, 0.5f, &lim, dt))
            arrived = k + 1;
    }
    CHECK(furthest <= 10000.0f + 0.01f);
    CHECK(arrived > 0 && fabsf((float)arrived * dt - 0.45f) <= 3.0f * dt);
    CHECK_EQ(a.pos, 10000.0f);
    CHECK_EQ(a.vel, 0.0f);
}

static void reversal_decelerates_within_the_limit(void)
{
    const axis_limits_t lim = {-20000.0f, 20000.0f, 25000.0f, 500000.0f};
    axis_t a = {0.0f, 25000.0f};
    float v0 = a.vel;
    axis_step(&a, -10000.0f, &lim, 1.0f, 0.004f);
    CHECK(fabsf((v0 - a.vel) - 2000.0f) < 1e-2f); /* exactly amax * dt of braking */
}

static void soft_limits_clamp_targets(void)
{
    const axis_limits_t lim = {500.0f, 14500.0f, 25000.0f, 500000.0f};
    axis_t a = {14000.0f, 0.0f};
    int k;
    uint8_t acted = 0;
    for (k = 0; k < 200; k++)
        acted |= axis_step(&a, 32767.0f, &lim, 1.0f, 0.004f);
    CHECK(acted & LIM_SOFT);
    CHECK_EQ(a.pos, 14500.0f);
}

static void an_axis_outside_its_limits_comes_back_without_a_jump(void)
{
    const axis_limits_t lim = {500.0f, 14500.0f, 25000.0f, 500000.0f};
    axis_t a = {14900.0f, 0.0f};
    float prev = a.pos, worst_jump = 0.0f;
    int k;
    for (k = 0; k < 100; k++) { /* a target further out is clamped inside: it comes back in */
        axis_step(&a, 20000.0f, &lim, 1.0f, 0.004f);
        worst_jump = fmaxf(worst_jump, fabsf(a.pos - prev));
        prev = a.pos;
    }
    CHECK_EQ(a.pos, 14500.0f);
    CHECK(worst_jump <= 25000.0f * 0.004f + 1e-3f);
    a.pos = 14900.0f;
    a.vel = 0.0f;
    axis_step(&a, 14000.0f, &lim, 1.0f, 0.004f); /* first step from outside: small, inward */
    CHECK(a.pos < 14900.0f && a.pos > 14890.0f);
}

int main(void)
{
    limits_hold_for_random_targets();
    step_arrives_on_time_without_overshoot();
    reversal_decelerates_within_the_limit();
    soft_limits_clamp_targets();
    an_axis_outside_its_limits_comes_back_without_a_jump();
    return CHECK_DONE("test_motion");
}
