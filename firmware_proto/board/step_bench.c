/* The control step's cost on the ATmega2560 (16 MHz), run in simavr: make avr-step-bench.
 * Drives the core to RUNNING (platform6, 6 actuators, feedback), then times, with Timer1 at
 * the CPU clock, one period's work: receiving a 6-actuator TARGET frame and device_step. */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <stdio.h>
#include <string.h>

#include "device.h"

static int uart_putchar(char c, FILE *stream)
{
    (void)stream;
    while (!(UCSR0A & _BV(UDRE0)))
        ;
    UDR0 = (uint8_t)c;
    return 0;
}
static FILE uart = FDEV_SETUP_STREAM(uart_putchar, 0, _FDEV_SETUP_WRITE);

static int emit(void *ctx, const uint8_t *b, size_t n) { (void)ctx; (void)b; (void)n; return 1; }

static uint16_t seq;
static void send(device_t *d, uint8_t type, const uint8_t *body, size_t len, uint32_t now)
{
    uint8_t wire[LINK_MAX_ENCODED + 1];
    size_t n = link_encode(type, seq++, body, len, wire);
    device_receive(d, wire, n, now);
}

static uint16_t target_body(uint8_t *body, uint32_t k)
{
    uint8_t i, *p = body + 1;
    body[0] = 6;
    for (i = 0; i < 6; i++)
        p = link_put_u16(p, (uint16_t)(7500 + (int16_t)((k * 37u + i * 500u) % 2000u) - 1000));
    return 13;
}

int main(void)
{
    static device_t d;
    static device_inputs_t in;
    uint8_t body[32];
    uint32_t now = 0, k, worst = 0, total = 0, steps = 0, rx_total = 0, axis_total = 0;
    uint8_t i;
    UCSR0B = _BV(TXEN0);
    stdout = &uart;
    device_init(&d, profile_find("platform6"), 0, emit, 0, 0, now, 0);
    in.has_feedback = 1;
    send(&d, LINK_HELLO, body, 0, now);
    body[0] = 9;
    memcpy(body + 1, "platform6", 9);
    send(&d, LINK_ARM, body, 10, now);
    TCCR1B = _BV(CS11); /* Timer1 at 2 MHz: 0.5 us, 8 cycles a count */
    for (k = 0; k < 1500; k++) {
        uint8_t wire[LINK_MAX_ENCODED + 1];
        size_t n = link_encode(LINK_TARGET, seq++, body, target_body(body, k), wire);
        uint16_t t0, t1;
        for (i = 0; i < 6; i++)
            in.measured[i] = device_commanded(&d, i);
        now += d.profile->period_ms;
        TCNT1 = 0;
        t0 = TCNT1;
        device_receive(&d, wire, n, now);
        rx_total += (uint16_t)(TCNT1 - t0);
        device_step(&d, &in, now);
        t1 = TCNT1;
        if (d.state == ST_RUNNING) {
            uint32_t cycles = 8ul * (uint16_t)(t1 - t0);
            axis_t a = d.axis[0];
            uint16_t a0 = TCNT1;
            axis_step(&a, 9000.0f, &d.limits[0], 1.0f, 0.004f);
            axis_total += 8ul * (uint16_t)(TCNT1 - a0);
            worst = cycles > worst ? cycles : worst;
            total += cycles;
            steps++;
        }
    }
    steps = steps ? steps : 1;
    printf("avr crc16(\"123456789\") = 0x%04X (must be 0x29B1)\n",
           link_crc16((const uint8_t *)"123456789", 9));
    printf("avr control period (a TARGET frame in + device_step, platform6, 6 actuators, running): %lu periods, "
           "mean %lu us, worst %lu us; of which receiving the frame %lu us, one axis_step %lu us\n",
           (unsigned long)steps, (unsigned long)(total / steps / 16), (unsigned long)(worst / 16),
           (unsigned long)(rx_total * 8ul / 1500ul / 16ul), (unsigned long)(axis_total / steps / 16));
    cli();
    sleep_mode(); /* simavr stops here */
    return 0;
}
