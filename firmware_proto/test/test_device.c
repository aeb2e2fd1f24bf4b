/* The device core: lifecycle, commands in every state, dead-man, e-stop, limits, bad input.
 * A fake clock and a perfect (or stuck) actuator; frames built with the link encoder. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "device.h"
#include "device_harness.h"

static void boots_disarmed_and_nothing_moves_without_arm(void)
{
    boot("servo8");
    CHECK_EQ(d.state, ST_DISARMED);
    CHECK_EQ(d.outputs_on, 0);
    send(LINK_HELLO);
    run_ms(500, 4000); /* targets while disarmed: refused, counted, no motion, no STATUS */
    CHECK_EQ(d.state, ST_DISARMED);
    CHECK_EQ(d.outputs_on, 0);
    CHECK_EQ(device_commanded(&d, 0), 0);
    CHECK_EQ(d.counters[C_REFUSED], 125);
    CHECK_EQ(d.last_reason, REASON_NOT_ARMED);
    CHECK_EQ(out.statuses, 0);
    CHECK(out.telemetry >= 20); /* 50 Hz while the link is alive */
    CHECK_EQ(named(LINK_ARM, "platform6"), REASON_WRONG_DEVICE);
    CHECK_EQ(d.state, ST_DISARMED);
    CHECK_EQ(command(LINK_RESET), REASON_OK); /* reset never arms */
    CHECK_EQ(d.state, ST_DISARMED);
    CHECK_EQ(command(LINK_PARK), REASON_OK);
    CHECK_EQ(d.state, ST_DISARMED);
}

static void arm_soft_start_run_under_limits(void)
{
    float worst_v = 0.0f, last[LINK_MAX_ACTUATORS] = {0};
    uint32_t t0, soft_ms = 0;
    uint8_t i;
    boot("servo8");
    send(LINK_HELLO);
    CHECK_EQ(named(LINK_ARM, "servo8"), REASON_OK);
    CHECK_EQ(out.last.state, ST_SOFT_START);
    CHECK_EQ(d.outputs_on, 1);
    run_ms(200, NO_TARGET); /* holds until the first target */
    CHECK_EQ(device_commanded(&d, 0), 0);
    t0 = now;
    while (now - t0 < 8000) {
        target_all(6000);
        step();
        for (i = 0; i < d.profile->actuators; i++) {
            float v = fabsf(d.axis[i].pos - last[i]) / 0.004f;
            worst_v = v > worst_v ? v : worst_v;
            last[i] = d.axis[i].pos;
        }
        if (!soft_ms && d.state == ST_RUNNING)
            soft_ms = now - t0;
    }
    /* 60 deg at 0.2 x 300 deg/s = 1 s, the shortest soft start (+ the smoothstep's own shape) */
    CHECK(soft_ms >= 1000 && soft_ms <= 1100);
    CHECK(worst_v <= 30000.0f * 1.001f);
    CHECK_EQ(device_commanded(&d, 3), 6000);
    CHECK_EQ(d.state, ST_RUNNING);
    target_all(30000); /* beyond the soft limit: clamped, counted */
    run_ms(1000, 30000);
    CHECK_EQ(device_commanded(&d, 0), 8500);
    CHECK(d.counters[C_CLIPPED] >= 200);
}

static void platform_homes_before_the_first_arm(void)
{
    uint32_t t0;
    boot("platform6");
    in.has_feedback = 1;
    send(LINK_HELLO);
    CHECK_EQ(named(LINK_ARM, "platform6"), REASON_OK);
    CHECK_EQ(d.state, ST_HOMING);
    t0 = now;
    while (d.state == ST_HOMING && now - t0 < 10000)
        run_ms(4, NO_TARGET);
    CHECK_EQ(d.state, ST_SOFT_START);
    CHECK_EQ(d.homed, 1);
    CHECK(abs(device_commanded(&d, 5) - 7500) <= d.profile->settle_counts);
    /* 70 mm at 0.2 x 250 mm/s = 1.4 s, plus braking and the last ms */
    CHECK(now - t0 >= 1400 && now - t0 <= 1600);
    CHECK_EQ(command(LINK_PARK), REASON_OK);
    run_ms(5000, NO_TARGET);
    CHECK_EQ(d.state, ST_PARKED);
    CHECK_EQ(d.outputs_on, 0);
    CHECK_EQ(device_commanded(&d, 0), 500);
    CHECK_EQ(named(LINK_ARM, "platform6"), REASON_OK); /* homed: straight to soft start */
    CHECK_EQ(d.state, ST_SOFT_START);
    CHECK_EQ(command(LINK_DISARM), REASON_OK);
    CHECK_EQ(d.state, ST_PARKING);
    run_ms(100, NO_TARGET);
    CHECK_EQ(d.state, ST_PARKED);
    CHECK_EQ(command(LINK_DISARM), REASON_OK);
    CHECK_EQ(d.state, ST_DISARMED);
}

static void running_servo(void)
{
    boot("servo8");
    send(LINK_HELLO);
    named(LINK_ARM, "servo8");
    run_ms(1500, 3000);
    CHECK_EQ(d.state, ST_RUNNING);
}

static void deadman_parks_then_faults(void)
{
    uint32_t last_frame, parked_at = 0;
    float prev;
    running_servo();
    last_frame = d.last_rx_ms;
    prev = d.axis[0].pos;
    while (d.state == ST_RUNNING && now - last_frame < 1000)
        step();
    /* first park step within the timeout + one control period of the last valid frame */
    CHECK_EQ(d.state, ST_PARKING);
    CHECK(now - last_frame >= 200 && now - last_frame <= 204);
    CHECK(d.axis[0].pos < prev); /* that step already moved toward park (0) */
    CHECK_EQ(d.counters[C_DEADMAN], 1);
    target_all(3000); /* a frame now does not resume motion */
    CHECK_EQ(d.last_reason, REASON_NOT_ARMED);
    while (d.state == ST_PARKING && now - last_frame < 5000) {
        CHECK(d.axis[0].pos <= prev + 1e-3f);
        prev = d.axis[0].pos;
        step();
        parked_at = now;
    }
    CHECK_EQ(d.state, ST_FAULT);
    CHECK_EQ(d.outputs_on, 0);
    CHECK_EQ(device_commanded(&d, 0), 0);
    CHECK_EQ(d.faults, F_LINK_TIMEOUT);
    CHECK(parked_at - last_frame <= 200 + 1500); /* 30 deg at 75 deg/s: 0.4 s */
    CHECK_EQ(named(LINK_ARM, "servo8"), REASON_LATCHED);
    CHECK_EQ(command(LINK_RESET), REASON_OK);
    CHECK_EQ(d.state, ST_DISARMED);
    CHECK_EQ(d.faults, 0);
}

static void heartbeats_keep_it_running_and_config_sets_the_timeout(void)
{
    running_servo();
    run_ms(2000, NO_TARGET); /* heartbeats only: holds the last target */
    CHECK_EQ(d.state, ST_RUNNING);
    CHECK_EQ(config(K_HEARTBEAT_TIMEOUT_MS, 0, 50), REASON_MOVING);
    command(LINK_PARK);
    run_ms(1000, NO_TARGET);
    CHECK_EQ(d.state, ST_PARKED);
    CHECK_EQ(config(K_HEARTBEAT_TIMEOUT_MS, 0, 50), REASON_OK);
    CHECK_EQ(config(K_HEARTBEAT_TIMEOUT_MS, 0, 5000), REASON_OUT_OF_RANGE);
    CHECK_EQ(config(K_HEARTBEAT_TIMEOUT_MS, 0, 19), REASON_OUT_OF_RANGE);
    named(LINK_ARM, "servo8");
    {
        uint32_t last_frame = d.last_rx_ms;
        while (d.state == ST_SOFT_START && now - last_frame < 1000)
            step();
        CHECK(now - last_frame >= 50 && now - last_frame <= 54);
        CHECK_EQ(d.state, ST_FAULT); /* it was at park already: parked in the same step */
        CHECK_EQ(d.faults, F_LINK_TIMEOUT);
    }
}

static void estop_from_link_and_input_is_latched(void)
{
    running_servo();
    CHECK_EQ(command(LINK_ESTOP), REASON_OK);
    CHECK_EQ(d.state, ST_ESTOP); /* at once, before the next step */
    CHECK_EQ(d.outputs_on, 0);
    CHECK_EQ(named(LINK_ARM, "servo8"), REASON_LATCHED);
    CHECK_EQ(command(LINK_PARK), REASON_LATCHED);
    CHECK_EQ(config(K_PWM_HZ, 0, 100), REASON_LATCHED);
    target_all(0);
    CHECK_EQ(d.last_reason, REASON_NOT_ARMED);
    run_ms(500, NO_TARGET);
    CHECK_EQ(d.outputs_on, 0);
    CHECK_EQ(device_commanded(&d, 0), 3000); /* nothing moved */
    in.estop_input = 1; /* the button, too */
    step();
    CHECK_EQ(d.faults, F_ESTOP_LINK | F_ESTOP_INPUT);
    CHECK_EQ(command(LINK_RESET), REASON_ESTOP_INPUT);
    CHECK_EQ(d.state, ST_ESTOP);
    in.estop_input = 0;
    step();
    CHECK_EQ(command(LINK_RESET), REASON_OK);
    CHECK_EQ(d.state, ST_DISARMED);
    run_ms(500, NO_TARGET);
    CHECK_EQ(d.outputs_on, 0); /* reset never restarts motion */
    CHECK_EQ(named(LINK_ARM, "servo8"), REASON_OK);
    run_ms(1500, 0);
    CHECK_EQ(d.state, ST_RUNNING);
    CHECK_EQ(device_commanded(&d, 0), 0);
    in.estop_input = 1; /* the input alone, while running */
    device_estop(&d, F_ESTOP_INPUT);
    CHECK_EQ(d.state, ST_ESTOP);
    in.estop_input = 1;
    step();
    CHECK_EQ(named(LINK_ARM, "servo8"), REASON_LATCHED);
}

static void stale_and_replayed_frames_are_never_acted_on(void)
{
    uint16_t arm_seq, last;
    boot("servo8");
    send(LINK_HELLO);
    arm_seq = seq;
    named(LINK_ARM, "servo8");
    command(LINK_PARK);
    run_ms(100, NO_TARGET);
    CHECK_EQ(d.state, ST_PARKED);
    { /* the ARM again, byte for byte */
        uint8_t body[7] = {6, 's', 'e', 'r', 'v', 'o', '8'};
        int before = out.statuses;
        send_raw(LINK_ARM, arm_seq, body, sizeof body);
        CHECK_EQ(out.statuses, before); /* no answer: it never got past the seq check */
    }
    CHECK_EQ(d.state, ST_PARKED);
    CHECK_EQ(d.counters[C_RX_STALE], 1);
    last = (uint16_t)(seq - 1u);
    seq = (uint16_t)(last + 40000u); /* a jump of more than half the window is "older" */
    send(LINK_HEARTBEAT);
    CHECK_EQ(d.counters[C_RX_STALE], 2);
    seq = (uint16_t)(last + 10u); /* a gap of 9: accepted, counted */
    send(LINK_HEARTBEAT);
    CHECK_EQ(d.counters[C_RX_STALE], 2);
    CHECK_EQ(d.counters[C_RX_GAP], 9);
    seq = 7; /* a new session restarts the window anywhere */
    send(LINK_HELLO);
    CHECK_EQ(named(LINK_ARM, "servo8"), REASON_OK);
}

static void a_new_session_parks_a_moving_device(void)
{
    running_servo();
    seq = 0;
    send(LINK_HELLO);
    CHECK_EQ(d.state, ST_PARKING);
    run_ms(2000, NO_TARGET);
    CHECK_EQ(d.state, ST_PARKED);
    CHECK_EQ(d.faults, 0);
}

static void config_only_tightens(void)
{
    boot("servo8");
    send(LINK_HELLO);
    CHECK_EQ(config(K_SOFT_MAX, 2, 2000), REASON_OK);
    CHECK_EQ(config(K_SOFT_MAX, 2, 9000), REASON_OUT_OF_RANGE); /* wider than the profile */
    CHECK_EQ(config(K_SOFT_MIN, 2, 2000), REASON_OUT_OF_RANGE); /* not below its max */
    CHECK_EQ(config(K_SOFT_MIN, 8, 0), REASON_UNKNOWN_KEY);      /* no actuator 8 */
    CHECK_EQ(config(K_SOFT_MIN, 1, 100), REASON_OUT_OF_RANGE);   /* park (0) would be outside */
    CHECK_EQ(config(K_SOFT_MAX, 1, -100), REASON_OUT_OF_RANGE);
    CHECK_EQ(config(K_VELOCITY_LIMIT, 0, 0), REASON_OUT_OF_RANGE);
    CHECK_EQ(config(K_VELOCITY_LIMIT, 0, 30001), REASON_OUT_OF_RANGE);
    CHECK_EQ(config(K_ACCELERATION_LIMIT, 0, 100000), REASON_OK);
    CHECK_EQ(config(K_PWM_HZ, 0, 330), REASON_OK);
    CHECK_EQ(config(K_PWM_HZ, 0, 331), REASON_OUT_OF_RANGE);
    CHECK_EQ(config(99, 0, 1), REASON_UNKNOWN_KEY);
    CHECK_EQ(d.counters[C_REFUSED], 9);
    named(LINK_ARM, "servo8");
    run_ms(3000, 5000);
    CHECK_EQ(device_commanded(&d, 2), 2000);
    CHECK_EQ(device_commanded(&d, 1), 5000);
}

static void wrong_count_and_device_frames_are_refused(void)
{
    uint8_t body[5] = {2, 1, 0, 2, 0}, status[7] = {0};
    running_servo();
    send_raw(LINK_TARGET, seq++, body, sizeof body);
    CHECK_EQ(d.last_reason, REASON_BAD_COUNT);
    send_raw(LINK_STATUS, seq++, status, sizeof status); /* a device -> host frame: not for us */
    CHECK_EQ(d.counters[C_RX_TYPE], 1);
    CHECK_EQ(command(LINK_RESET), REASON_MOVING);
    CHECK_EQ(named(LINK_HOME, "servo8"), REASON_MOVING);
    CHECK_EQ(device_commanded(&d, 0), 3000);
}

static void following_error_parks_then_faults(void)
{
    boot("platform6");
    in.has_feedback = 1;
    send(LINK_HELLO);
    named(LINK_ARM, "platform6");
    run_ms(3000, NO_TARGET);
    CHECK_EQ(d.state, ST_SOFT_START);
    stuck = 4;
    run_ms(2500, 12000); /* actuator 4 stays behind by more than 10 mm for 200 ms */
    CHECK_EQ(d.state, ST_FAULT);
    CHECK_EQ(d.faults, F_FOLLOWING_ERROR);
    CHECK_EQ(d.outputs_on, 0);
}

static void a_noisy_link_parks_a_moving_device(void)
{
    static const uint8_t bad_packet[] = {0x05, 0x11, 0x22, 0x00}; /* a COBS error */
    int k;
    running_servo();
    for (k = 0; k < 100; k++) { /* 5 rejected packets a second, under the 10/s leak: runs on */
        device_receive(&d, bad_packet, sizeof bad_packet, now);
        run_ms(200, 3000);
    }
    CHECK_EQ(d.state, ST_RUNNING);
    CHECK_EQ(d.counters[C_RX_COBS], 100);
    for (k = 0; k < 26; k++) /* a burst over the budget of 25 */
        device_receive(&d, bad_packet, sizeof bad_packet, now);
    target_all(3000);
    step();
    CHECK_EQ(d.state, ST_PARKING);
    run_ms(2000, 3000);
    CHECK_EQ(d.state, ST_FAULT);
    CHECK_EQ(d.faults, F_LINK_ERRORS);
    CHECK_EQ(device_commanded(&d, 0), 0);
}

static void noise_never_moves_anything(void)
{
    uint32_t r = 99u;
    uint8_t noise[4096];
    int k;
    size_t i;
    boot("servo8");
    for (k = 0; k < 50; k++) {
        for (i = 0; i < sizeof noise; i++) {
            r = r * 1664525u + 1013904223u;
            noise[i] = (uint8_t)(r >> 24);
        }
        device_receive(&d, noise, sizeof noise, now);
        step();
    }
    CHECK_EQ(d.counters[C_RX_OK], 0);
    CHECK_EQ(d.state, ST_DISARMED);
    CHECK_EQ(d.outputs_on, 0);
    CHECK(d.counters[C_RX_COBS] + d.counters[C_RX_CRC] + d.counters[C_RX_SHORT] + d.counters[C_RX_OVERSIZE] > 500);
}

static void pulses_map_positions_to_the_profiles_outputs(void)
{
    const profile_t *servo = profile_find("servo8"), *platform = profile_find("platform6");
    CHECK_EQ(profile_pulse_us(servo, 0.0f), 1500);     /* centre */
    CHECK_EQ(profile_pulse_us(servo, 9000.0f), 2500);  /* +90 deg */
    CHECK_EQ(profile_pulse_us(servo, -4500.0f), 1000); /* -45 deg */
    CHECK_EQ(profile_pulse_us(servo, 30000.0f), 2500); /* clamped to the output range */
    CHECK_EQ(profile_pulse_us(platform, 0.0f), 1000);  /* retracted */
    CHECK_EQ(profile_pulse_us(platform, 7500.0f), 1500);
    CHECK_EQ(profile_pulse_us(platform, 15000.0f), 2000);
    CHECK(profile_find("nope") == 0);
    CHECK_EQ(servo->pwm_hz, 50);
}

/* The park is bounded in time, not in steps: a loop starved of steps (here one every
 * 250 ms instead of every period) still turns the outputs off PARK_BOUND_MS after the
 * park began, with F_PARK_TIMEOUT latched beside the dead-man's fault. */
static void a_starved_park_ends_in_outputs_off_within_the_bound(void)
{
    uint32_t began;
    running_servo();
    while (d.state == ST_RUNNING)
        step(); /* no frames: the dead-man parks */
    CHECK_EQ(d.state, ST_PARKING);
    began = d.state_since_ms;
    while (d.state == ST_PARKING && now - began < 60000u) {
        CHECK_EQ(d.outputs_on, 1);
        now += 250u - d.profile->period_ms; /* step() adds one period */
        step();
    }
    CHECK_EQ(d.state, ST_FAULT);
    CHECK_EQ(d.outputs_on, 0);
    CHECK_EQ(now - began, PARK_BOUND_MS); /* the first step at or past the bound: 20 x 250 ms */
    CHECK_EQ(d.faults, F_LINK_TIMEOUT | F_PARK_TIMEOUT);
    CHECK(device_commanded(&d, 0) > 0); /* it had not got there: stopped where it was */
    CHECK_EQ(named(LINK_ARM, "servo8"), REASON_LATCHED);
}

int main(void)
{
    boots_disarmed_and_nothing_moves_without_arm();
    arm_soft_start_run_under_limits();
    platform_homes_before_the_first_arm();
    deadman_parks_then_faults();
    a_starved_park_ends_in_outputs_off_within_the_bound();
    heartbeats_keep_it_running_and_config_sets_the_timeout();
    estop_from_link_and_input_is_latched();
    stale_and_replayed_frames_are_never_acted_on();
    a_new_session_parks_a_moving_device();
    config_only_tightens();
    wrong_count_and_device_frames_are_refused();
    following_error_parks_then_faults();
    a_noisy_link_parks_a_moving_device();
    noise_never_moves_anything();
    pulses_map_positions_to_the_profiles_outputs();
    return CHECK_DONE("test_device");
}
