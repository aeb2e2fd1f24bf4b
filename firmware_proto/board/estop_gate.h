/* The e-stop gate of a board: the edge interrupt, the read-and-clear of the edge it saw and
 * the check-then-enable of the outputs, with interrupts masked around both. One source for
 * the Mega 2560 (board/mega2560.c) and the host test that fires the edge at every point of
 * a control step (test/test_estop_edges.c): what the test proves is what the board runs.
 *
 * The includer defines, before including (statement-like macros):
 *   GATE_PIN()          1 while the e-stop input is open (contact open or wire cut)
 *   GATE_OUTPUTS_OFF()  disable every output now (enable low, pulses disconnected)
 *   GATE_OUTPUTS_ON()   connect the pulses and raise the enable
 *   GATE_MASK(s)        save the interrupt state into s (uint8_t) and mask interrupts
 *   GATE_UNMASK(s)      restore it; an edge that came while masked is served right here
 *   GATE_POINT()        nothing on a board; in the host test, a point where the edge may come
 * and calls gate_on_edge() from the edge interrupt (INT0 on the Mega).
 *
 * Why masked: an edge between reading gate_estop_seen and clearing it would be lost (a
 * short opening leaves no trace on the pin: outputs back on at the next step, no latch);
 * an edge between checking the pin and enabling the outputs would be undone until the next
 * step. Masked, the interrupt waits (its flag stays set) and runs at GATE_UNMASK: after the
 * clear (so it is seen at the next read) and after the enable (so it cuts the outputs).
 * An edge seen and not yet read keeps the outputs off too: the core latches it at its
 * next read of the input (fw.c reads it on every poll).
 */
#ifndef ESTOP_GATE_H
#define ESTOP_GATE_H

#include <stdint.h>

static volatile uint8_t gate_estop_seen; /* an opening the interrupt saw since the last read */

/* The edge interrupt: the input opened, cut the outputs now; the core latches at its next read. */
static void gate_on_edge(void)
{
    if (GATE_PIN()) {
        GATE_OUTPUTS_OFF();
        gate_estop_seen = 1;
    }
}

/* hal_estop_input: the pin, or an opening the interrupt saw since the last call (then forgotten). */
static int gate_estop_input(void)
{
    uint8_t sreg;
    int active;
    GATE_MASK(sreg);
    GATE_POINT();
    active = GATE_PIN() != 0;
    GATE_POINT();
    active |= gate_estop_seen != 0;
    GATE_POINT();
    gate_estop_seen = 0;
    GATE_POINT();
    GATE_UNMASK(sreg);
    return active;
}

/* hal_write_outputs' last act: enable the outputs if on, the pin is closed and no opening
 * waits to be read; else disable them. Returns 1 if it enabled them. */
static int gate_outputs(int on)
{
    uint8_t sreg;
    int enable;
    GATE_MASK(sreg);
    GATE_POINT();
    enable = on && !GATE_PIN() && !gate_estop_seen;
    GATE_POINT();
    if (enable)
        GATE_OUTPUTS_ON();
    else
        GATE_OUTPUTS_OFF();
    GATE_POINT();
    GATE_UNMASK(sreg);
    return enable;
}

#endif
