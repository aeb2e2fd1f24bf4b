/* The device core: link frames in, lifecycle, dead-man, limited motion, frames out.
 *
 * Pure C99: no clock, no I/O. The caller passes the time (ms) and the inputs, and gets the
 * commanded positions and the output enable back in the struct; frames go out through
 * the emit callback. fw.c wires it to the HAL; the tests drive it directly.
 *
 * States (coord/LIFECYCLE.md): boots DISARMED, outputs off. ARM (naming the device) ->
 * HOMING (first time, profiles that need it) -> SOFT_START -> RUNNING. PARK / DISARM /
 * a new HELLO -> PARKING -> PARKED. E-stop (input or link) -> ESTOP at once, outputs off,
 * latched. Dead-man (no valid frame for heartbeat_ms while outputs are on), a noisy link
 * (rejected packets over the profile's budget), following error -> PARKING, then FAULT,
 * latched. RESET -> DISARMED, never motion.
 */
#ifndef DEVICE_H
#define DEVICE_H

#include <stddef.h>
#include <stdint.h>

#include "link.h"
#include "motion.h"
#include "profile.h"

#define FW_VERSION_MAJOR 0
#define FW_VERSION_MINOR 1

/* Queue one whole frame for sending; return 0 if it cannot (the frame is dropped, counted). */
typedef int (*device_emit_fn)(void *ctx, const uint8_t *bytes, size_t n);
/* Called for every frame the device accepts (after CRC, version, length and seq checks). */
typedef void (*device_observe_fn)(void *ctx, const link_frame_t *frame);

typedef struct {
    uint8_t estop_input;  /* 1: the e-stop input is active (contact open or wire cut) */
    uint8_t has_feedback; /* 1: measured holds the actuators' positions */
    int16_t measured[LINK_MAX_ACTUATORS];
} device_inputs_t;

typedef struct {
    const profile_t *profile;
    char name[LINK_MAX_NAME + 1];
    device_emit_fn emit;
    device_observe_fn observe;
    void *ctx;
    link_rx_t rx;

    uint8_t state;          /* link_state_t */
    uint8_t outputs_on;     /* drive the actuators (else outputs disabled) */
    uint8_t homed, arm_after_homing, has_target, limited, estop_input, has_feedback;
    uint8_t link_seen, following, telemetry_now, last_reason;
    uint16_t faults, pending_faults; /* latched, and to latch once parked */
    link_seq_t rx_seq;
    uint16_t tx_seq;
    uint16_t parks; /* parks begun since boot (the host build reports each first park step) */
    uint16_t counters[C_COUNT];
    uint32_t now_ms, last_rx_ms, state_since_ms, last_telemetry_ms, follow_since_ms;
    float link_errors; /* the leaky bucket of rejected packets */

    uint16_t heartbeat_ms, telemetry_ms, pwm_hz; /* live config */
    axis_limits_t limits[LINK_MAX_ACTUATORS];
    axis_t axis[LINK_MAX_ACTUATORS];             /* commanded motion */
    int16_t target[LINK_MAX_ACTUATORS];          /* latest accepted target, clamped */
    float blend_from[LINK_MAX_ACTUATORS];        /* soft start: where it began */
    int16_t measured[LINK_MAX_ACTUATORS];
} device_t;

/* Boot: DISARMED, outputs off, commanded = start (the measured positions, or 0 for the park pose). */
void device_init(device_t *d, const profile_t *profile, const char *name, device_emit_fn emit,
                 device_observe_fn observe, void *ctx, uint32_t now_ms, const int16_t *start);
/* Bytes from the link. */
void device_receive(device_t *d, const uint8_t *bytes, size_t n, uint32_t now_ms);
/* One control period: e-stop input, dead-man, lifecycle, motion, telemetry. */
void device_step(device_t *d, const device_inputs_t *in, uint32_t now_ms);
/* Latch the e-stop at once (an input interrupt between two steps). */
void device_estop(device_t *d, uint16_t fault_bit);

const char *device_state_name(uint8_t state);
int16_t device_commanded(const device_t *d, uint8_t i); /* rounded counts */

#endif
