/* The e-stop edge at every point of a control step: fw.c and the core over a host HAL whose
 * e-stop input and outputs go through the board's own gate (board/estop_gate.h), with an
 * interrupt that can fire between any two of its operations.
 *
 * A point is each place the HAL reaches (every call, and between every two operations of
 * the gate). The edge fires at point k of a poll that runs a control step, for every k: at
 * once if interrupts are enabled, else when they are unmasked (the flag waits, as INT0's
 * does). Two kinds of edge: the contact stays open, or it closes again right after the
 * interrupt has run (a short press, a bounce: the pin no longer tells). After each, the
 * outputs must be off at the end of that poll and never enabled again once the interrupt
 * cut them (an enable inside a masked section the edge came into is cut at the unmask, a
 * few cycles on the MCU), and the device must be latched (ESTOP, F_ESTOP_INPUT) after the
 * next poll: 0 lost edges.
 *
 * The same sweep with the masks turned off (GATE_MASK doing nothing, as before) must
 * find lost edges or outputs enabled after an edge: the sweep reaches the windows.
 */
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fw.h"
#include "hal.h"

static struct {
    int pin;      /* e-stop input: 1 open */
    int enabled;  /* the outputs' enable line */
    int masking;  /* 1: GATE_MASK masks (the board); 0: it does nothing (the old firmware) */
    int masked, pending;
    int pulse;    /* 1: the contact closes again right after the interrupt ran */
    int fired;    /* the edge came */
    int served;   /* its interrupt ran (and cut the outputs) */
    long point, fire_at;
    long enabled_after_cut; /* outputs enabled again after the interrupt cut them: must stay 0 */
    uint32_t ms;
    uint8_t rx[256];
    size_t rx_len, rx_pos;
} sim;

static void point(void);
static void unmask(uint8_t state);
static void outputs_enable(void);

#define GATE_PIN() (sim.pin)
#define GATE_OUTPUTS_OFF() (sim.enabled = 0)
#define GATE_OUTPUTS_ON() outputs_enable()
#define GATE_MASK(s) ((s) = (uint8_t)sim.masked, sim.masked = sim.masking)
#define GATE_UNMASK(s) unmask(s)
#define GATE_POINT() point()
#include "estop_gate.h"

static void interrupt(void) /* INT0: the board's ISR body, then maybe the contact closes again */
{
    gate_on_edge();
    sim.served = 1;
    if (sim.pulse)
        sim.pin = 0;
}

static void point(void)
{
    if (++sim.point != sim.fire_at)
        return;
    sim.pin = 1;
    sim.fired = 1;
    if (sim.masked)
        sim.pending = 1;
    else
        interrupt();
}

static void unmask(uint8_t state)
{
    sim.masked = state;
    if (!sim.masked && sim.pending) {
        sim.pending = 0;
        interrupt();
    }
}

static void outputs_enable(void)
{
    sim.enabled = 1;
    if (sim.served)
        sim.enabled_after_cut++;
}

/* --- the HAL (the board's, over the simulation) --- */

uint32_t hal_millis(void)
{
    point();
    return sim.ms;
}

size_t hal_serial_read(uint8_t *buf, size_t cap)
{
    size_t n = sim.rx_len - sim.rx_pos;
    point();
    n = n < cap ? n : cap;
    memcpy(buf, sim.rx + sim.rx_pos, n);
    sim.rx_pos += n;
    return n;
}

int hal_serial_write(const uint8_t *bytes, size_t n)
{
    (void)bytes;
    (void)n;
    point();
    return 1;
}

int hal_estop_input(void) { return gate_estop_input(); }

int hal_read_feedback(int16_t *measured, uint8_t n)
{
    (void)measured;
    (void)n;
    point();
    return 0;
}

void hal_write_outputs(const device_t *d)
{
    point(); /* the widths (mega2560.c: ICRn, OCRnx) before the gate */
    gate_outputs(d->outputs_on);
}

/* --- the sweep --- */

static fw_t fw;
static uint16_t seq;

static void queue(uint8_t type, const char *name)
{
    uint8_t body[1 + LINK_MAX_NAME];
    size_t len = 0;
    if (name) {
        body[0] = (uint8_t)strlen(name);
        memcpy(body + 1, name, body[0]);
        len = 1u + body[0];
    }
    sim.rx_len += link_encode(type, seq++, body, len, sim.rx + sim.rx_len);
}

static void run_step(void) /* time moves to the next step, a heartbeat arrives, one poll */
{
    sim.ms += fw.device.profile->period_ms;
    queue(LINK_HEARTBEAT, 0);
    CHECK_EQ(fw_poll(&fw), 1);
}

/* Boot, arm and run until the outputs are on; then a step with the edge at point fire_at.
 * Returns the points that step reached; counts what went wrong in *lost and *reenabled. */
static long trial(long fire_at, int pulse, int masking, long *lost, long *reenabled)
{
    long reached;
    memset(&sim, 0, sizeof sim);
    sim.masking = masking;
    sim.fire_at = -1;
    sim.ms = 1000;
    seq = 1;
    fw_init(&fw, profile_find("servo8"), 0, 0, 0);
    queue(LINK_HELLO, 0);
    queue(LINK_ARM, "servo8");
    run_step();
    run_step();
    CHECK_EQ(fw.device.state, ST_SOFT_START);
    CHECK(sim.enabled && !sim.fired);
    sim.rx_len = sim.rx_pos = 0;
    sim.point = 0;
    sim.fire_at = fire_at;
    sim.pulse = pulse;
    run_step();
    reached = sim.point;
    if (fire_at < 0)
        return reached;
    CHECK(sim.fired);
    CHECK(!sim.pending && !sim.masked);
    if (sim.enabled) /* the poll in which the edge came ends with the outputs off */
        (*reenabled)++;
    sim.rx_len = sim.rx_pos = 0;
    fw_poll(&fw); /* the next poll (no step due) reads the input */
    run_step();   /* and a whole step */
    if (fw.device.state != ST_ESTOP || !(fw.device.faults & F_ESTOP_INPUT) || fw.device.outputs_on)
        (*lost)++;
    if (sim.enabled_after_cut || sim.enabled)
        (*reenabled)++;
    return reached;
}

static void sweep(int masking, long *points, long *lost, long *reenabled)
{
    long dummy = 0, k;
    int pulse;
    *points = trial(-1, 0, masking, &dummy, &dummy);
    *lost = *reenabled = 0;
    for (pulse = 0; pulse <= 1; pulse++)
        for (k = 1; k <= *points; k++) {
            long before = *lost + *reenabled;
            trial(k, pulse, masking, lost, reenabled);
            if (getenv("EDGES_VERBOSE") && *lost + *reenabled != before) /* which points, to debug */
                printf("  masking %d pulse %d point %ld: lost %ld, on after the cut %ld\n", masking, pulse, k, *lost,
                       *reenabled);
        }
}

int main(void)
{
    long points, lost, reenabled;
    sweep(1, &points, &lost, &reenabled);
    printf("test_estop_edges: masked (the board): %ld points a step x 2 kinds of edge: %ld lost, %ld with "
           "outputs on after the cut\n",
           points, lost, reenabled);
    /* the HAL calls of a step (fw_poll: 2 reads, 2 clocks, 2 e-stop inputs of 4 points, the
     * feedback, the outputs with the gate's 3) */
    CHECK(points >= 17);
    CHECK_EQ(lost, 0);
    CHECK_EQ(reenabled, 0);
    sweep(0, &points, &lost, &reenabled);
    printf("test_estop_edges: masks off (the windows they close): %ld lost, %ld with outputs on after the cut\n", lost,
           reenabled);
    CHECK(lost > 0);      /* the read-and-clear window: a short opening between the two */
    CHECK(reenabled > 0); /* the check-then-enable window */
    return CHECK_DONE("test_estop_edges");
}
