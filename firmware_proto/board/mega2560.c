/* Board shim: Arduino Mega 2560 (ATmega2560, 16 MHz), bare avr-libc, no Arduino core.
 *
 * Pins (Arduino numbering):
 *   D0/D1   link: USART0 through the board's USB serial chip, 250000 baud 8N1 (exact at 16 MHz)
 *   D21     e-stop input (PD0/INT0), pull-up: wire a normally-closed contact to GND;
 *           open contact or a cut wire reads high = e-stop, caught by interrupt
 *   D22     outputs enable (PA0): high while outputs are on; drive the servo power relay
 *           or the actuator drivers' enable from it
 *   D11 D12 D13 D5 D2 D3 D6 D7   pulse outputs 0-7 (OC1A-C, OC3A-C, OC4A-B): 0.5 us steps
 *   A0-A5   position feedback for the platform profiles (pots, 0-5 V over the stroke)
 * A 60 ms watchdog resets a hung loop: the board boots DISARMED with outputs off.
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/wdt.h>

#include "fw.h"
#include "hal.h"

#ifndef FW_PROFILE
#define FW_PROFILE "platform6"
#endif
#ifndef FW_DEVICE_NAME
#define FW_DEVICE_NAME FW_PROFILE
#endif
/* The control period on this board: a 16 MHz AVR without an FPU needs about 3 ms for one
 * period of six actuators in soft float (make avr-step-bench), so it runs at 125 Hz. */
#define BOARD_PERIOD_MS 8

#define RX_SIZE 128u /* powers of two: the indexes wrap with a mask */
#define TX_SIZE 256u

static volatile uint32_t millis_count;
static volatile uint8_t rx_buf[RX_SIZE], rx_head, rx_tail;
static volatile uint8_t tx_buf[TX_SIZE], tx_head, tx_tail;
static uint16_t timer_top;
static profile_t board_profile_copy; /* the chosen profile at this board's control period */
static const profile_t *board_profile;

ISR(TIMER0_COMPA_vect) { millis_count++; }

ISR(USART0_RX_vect)
{
    uint8_t byte = UDR0, next = (uint8_t)((rx_head + 1u) & (RX_SIZE - 1u));
    if (next != rx_tail) { /* full: the byte is lost, the frame fails its CRC, counted */
        rx_buf[rx_head] = byte;
        rx_head = next;
    }
}

ISR(USART0_UDRE_vect)
{
    if (tx_head == tx_tail) {
        UCSR0B &= (uint8_t)~_BV(UDRIE0);
        return;
    }
    UDR0 = tx_buf[tx_tail];
    tx_tail = (uint8_t)((tx_tail + 1u) & (TX_SIZE - 1u));
}

static void outputs_off(void)
{
    PORTA &= (uint8_t)~_BV(PA0);
    TCCR1A = _BV(WGM11); /* compare outputs disconnected: the pins fall low, no pulses */
    TCCR3A = _BV(WGM31);
    TCCR4A = _BV(WGM41);
}

static void outputs_on(void)
{
    TCCR1A = _BV(COM1A1) | _BV(COM1B1) | _BV(COM1C1) | _BV(WGM11);
    TCCR3A = _BV(COM3A1) | _BV(COM3B1) | _BV(COM3C1) | _BV(WGM31);
    TCCR4A = _BV(COM4A1) | _BV(COM4B1) | _BV(WGM41);
    PORTA |= _BV(PA0);
}

/* The e-stop gate (estop_gate.h): interrupts masked by saving SREG and cli(), restored
 * with a compiler barrier, as avr-libc's ATOMIC_BLOCK(ATOMIC_RESTORESTATE) does. */
#define GATE_PIN() ((PIND & _BV(PD0)) != 0)
#define GATE_OUTPUTS_OFF() outputs_off()
#define GATE_OUTPUTS_ON() outputs_on()
#define GATE_MASK(s) \
    do { \
        (s) = SREG; \
        cli(); \
    } while (0)
#define GATE_UNMASK(s) \
    do { \
        __asm__ __volatile__("" ::: "memory"); \
        SREG = (s); \
    } while (0)
#define GATE_POINT() ((void)0)
#include "estop_gate.h"

ISR(INT0_vect) { gate_on_edge(); }

uint32_t hal_millis(void)
{
    uint8_t sreg = SREG;
    uint32_t ms;
    cli();
    ms = millis_count;
    SREG = sreg;
    return ms;
}

size_t hal_serial_read(uint8_t *buf, size_t cap)
{
    size_t n = 0;
    while (n < cap && rx_tail != rx_head) {
        buf[n++] = rx_buf[rx_tail];
        rx_tail = (uint8_t)((rx_tail + 1u) & (RX_SIZE - 1u));
    }
    return n;
}

int hal_serial_write(const uint8_t *bytes, size_t n)
{
    uint8_t free_bytes = (uint8_t)(tx_tail - tx_head - 1); /* uint8_t indexes wrap at TX_SIZE = 256 */
    size_t i;
    if (n > free_bytes)
        return 0; /* a reader that stops reading: drop whole frames, counted */
    for (i = 0; i < n; i++) {
        tx_buf[tx_head] = bytes[i];
        tx_head = (uint8_t)((tx_head + 1u) & (TX_SIZE - 1u));
    }
    UCSR0B |= _BV(UDRIE0);
    return 1;
}

int hal_estop_input(void) { return gate_estop_input(); }

int hal_read_feedback(int16_t *measured, uint8_t n)
{
    const profile_t *p = board_profile;
    uint8_t i;
    if (!p || !p->feedback)
        return 0;
    for (i = 0; i < n && i < 6; i++) {
        uint16_t raw;
        ADMUX = (uint8_t)(_BV(REFS0) | i); /* AVcc reference, channel i */
        ADCSRB = 0;
        ADCSRA |= _BV(ADSC);
        while (ADCSRA & _BV(ADSC))
            ;
        raw = ADC;
        measured[i] = (int16_t)(p->actuator.out_lo +
                                (int32_t)raw * (p->actuator.out_hi - p->actuator.out_lo) / 1023);
    }
    return 1;
}

static volatile uint16_t *const OCR[8] = {&OCR1A, &OCR1B, &OCR1C, &OCR3A, &OCR3B, &OCR3C, &OCR4A, &OCR4B};

void hal_write_outputs(const device_t *d)
{
    uint8_t i;
    uint16_t top = (uint16_t)(2000000UL / d->pwm_hz - 1u); /* 2 MHz timer clock */
    if (d->outputs_on) { /* the widths first (buffered to the next period), then the gate */
        if (top != timer_top) {
            ICR1 = ICR3 = ICR4 = top;
            timer_top = top;
        }
        for (i = 0; i < d->profile->actuators && i < 8; i++)
            *OCR[i] = (uint16_t)(profile_pulse_us(d->profile, d->axis[i].pos) * 2u);
    }
    gate_outputs(d->outputs_on);
}

static void board_init(void)
{
    /* USART0: 250000 baud, double speed, 8N1, RX interrupt */
    UCSR0A = _BV(U2X0);
    UBRR0 = 7;
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
    /* Timer0: 1 kHz tick */
    TCCR0A = _BV(WGM01);
    TCCR0B = _BV(CS01) | _BV(CS00);
    OCR0A = 249;
    TIMSK0 = _BV(OCIE0A);
    /* Timers 1, 3, 4: fast PWM, TOP = ICRn, clk/8 = 2 MHz; outputs start disconnected */
    TCCR1B = _BV(WGM13) | _BV(WGM12) | _BV(CS11);
    TCCR3B = _BV(WGM33) | _BV(WGM32) | _BV(CS31);
    TCCR4B = _BV(WGM43) | _BV(WGM42) | _BV(CS41);
    DDRB |= _BV(PB5) | _BV(PB6) | _BV(PB7);
    DDRE |= _BV(PE3) | _BV(PE4) | _BV(PE5);
    DDRH |= _BV(PH3) | _BV(PH4);
    DDRA |= _BV(PA0);
    outputs_off();
    /* e-stop: PD0 input with pull-up, interrupt on any change */
    DDRD &= (uint8_t)~_BV(PD0);
    PORTD |= _BV(PD0);
    EICRA = _BV(ISC00);
    EIMSK = _BV(INT0);
    /* ADC: enabled, clk/128 = 125 kHz */
    ADCSRA = _BV(ADEN) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0);
}

int main(void)
{
    static fw_t fw;
    wdt_enable(WDTO_60MS);
    board_init();
    sei();
    board_profile = profile_find(FW_PROFILE);
    if (!board_profile)
        for (;;) /* a build with an unknown profile never drives anything */
            wdt_reset();
    board_profile_copy = *board_profile;
    board_profile_copy.period_ms = BOARD_PERIOD_MS;
    board_profile = &board_profile_copy;
    fw_init(&fw, board_profile, FW_DEVICE_NAME, 0, 0);
    for (;;) {
        wdt_reset();
        fw_poll(&fw);
    }
}
