/* One actuator's commanded motion under soft, velocity and acceleration limits.
 *
 * Units: counts (0.01 mm or 0.01 deg), counts/s, counts/s^2; dt in seconds. Pure C99.
 */
#ifndef MOTION_H
#define MOTION_H

#include <stdint.h>

typedef struct {
    float pos; /* commanded position, counts */
    float vel; /* counts/s */
} axis_t;

typedef struct {
    float min, max; /* soft limits, counts */
    float vmax;     /* counts/s */
    float amax;     /* counts/s^2 */
} axis_limits_t;

enum { LIM_SOFT = 1, LIM_VELOCITY = 2, LIM_ACCELERATION = 4 };

/* Move one control period toward target (clamped to the soft limits) with |vel| <=
 * vscale * vmax and |dvel| <= amax * dt, braking so as to stop at a still target without
 * overshoot. Returns the LIM_* bits of the limits that acted. */
uint8_t axis_step(axis_t *axis, float target, const axis_limits_t *lim, float vscale, float dt);

/* True when the axis is within tolerance counts of where and (nearly) still. */
int axis_settled(const axis_t *axis, float where, float tolerance, const axis_limits_t *lim, float dt);

#endif
