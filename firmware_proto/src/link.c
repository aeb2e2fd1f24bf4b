/* The platform link codec; see link.h and docs/platform-link.md. */
#include "link.h"

#include <string.h>

const char *const LINK_COUNTER_NAMES[C_COUNT] = {
    "rx_ok",   "rx_cobs", "rx_short", "rx_oversize", "rx_crc",  "rx_version", "rx_type",   "rx_length",
    "rx_stale", "rx_gap", "refused",  "clipped",     "limited", "deadman",    "tx_dropped"};

/* CRC-16/IBM-3740 (alias CCITT-FALSE): poly 0x1021, init 0xFFFF, MSB first, no xorout.
 * Bitwise, no table in flash; on an AVR, avr-libc's _crc_xmodem_update is the same CRC step
 * (poly 0x1021, MSB first) in a few instructions. */
#ifdef __AVR__
#include <util/crc16.h>
#endif

uint16_t link_crc16(const uint8_t *data, size_t n)
{
    uint16_t crc = 0xFFFFu;
    while (n--) {
#ifdef __AVR__
        crc = _crc_xmodem_update(crc, *data++);
#else
        uint8_t bit;
        crc ^= (uint16_t)((uint16_t)*data++ << 8);
        for (bit = 0; bit < 8; bit++) {
            if (crc & 0x8000u)
                crc = (uint16_t)((unsigned)(crc << 1) ^ 0x1021u);
            else
                crc = (uint16_t)(crc << 1);
        }
#endif
    }
    return crc;
}

size_t link_cobs_encode(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t code_at = 0, o = 1, i;
    uint8_t code = 1;
    for (i = 0; i < n; i++) {
        if (in[i] == 0) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
            continue;
        }
        out[o++] = in[i];
        if (++code == 0xFF) { /* a full block: no zero implied after it */
            out[code_at] = code;
            code_at = o++;
            code = 1;
        }
    }
    out[code_at] = code;
    return o;
}

/* In place is allowed (out == in): the output never overtakes the input. */
size_t link_cobs_decode(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t i = 0, o = 0;
    while (i < n) {
        uint8_t code = in[i];
        size_t k;
        if (code == 0 || i + code > n)
            return SIZE_MAX;
        for (k = 1; k < code; k++) {
            if (in[i + k] == 0)
                return SIZE_MAX;
            out[o++] = in[i + k];
        }
        i += code;
        if (code != 0xFF && i < n)
            out[o++] = 0;
    }
    return o;
}

static uint16_t get_u16(const uint8_t *p) { return (uint16_t)(p[0] | (uint16_t)((uint16_t)p[1] << 8)); }

uint8_t *link_put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)(v >> 8);
    return p + 2;
}

uint8_t *link_put_u32(uint8_t *p, uint32_t v)
{
    return link_put_u16(link_put_u16(p, (uint16_t)(v & 0xFFFFu)), (uint16_t)(v >> 16));
}

/* Body length of a counted body: header bytes, then count (1..max) items, then a tail. */
static int counted_ok(const uint8_t *body, size_t len, size_t at, size_t item, size_t tail, uint8_t max)
{
    return len > at && body[at] >= 1 && body[at] <= max && len == at + 1u + item * body[at] + tail;
}

/* A counted name (1..16 bytes) of printable ASCII, 0x21-0x7E. */
static int name_ok(const uint8_t *body, size_t len, size_t at)
{
    size_t i;
    if (!counted_ok(body, len, at, 1, 0, LINK_MAX_NAME))
        return 0;
    for (i = at + 1; i < len; i++)
        if (body[i] < 0x21 || body[i] > 0x7E)
            return 0;
    return 1;
}

static int body_ok(uint8_t type, const uint8_t *body, size_t len)
{
    switch (type) {
    case LINK_HELLO: case LINK_DISARM: case LINK_PARK: case LINK_ESTOP: case LINK_RESET: case LINK_HEARTBEAT:
        return len == 0;
    case LINK_TARGET: return counted_ok(body, len, 0, 2, 0, LINK_MAX_ACTUATORS);
    case LINK_ARM: case LINK_HOME: return name_ok(body, len, 0);
    case LINK_CONFIG: return len == 6;
    case LINK_HELLO_REPLY: return name_ok(body, len, 8);
    case LINK_STATUS: return len == 7;
    default: /* LINK_TELEMETRY */ return counted_ok(body, len, 9, 4, 2u * C_COUNT, LINK_MAX_ACTUATORS);
    }
}

static int known_type(uint8_t type)
{
    return (type >= LINK_HELLO && type <= LINK_CONFIG) || (type >= LINK_HELLO_REPLY && type <= LINK_TELEMETRY);
}

link_rx_result_t link_parse(const uint8_t *frame, size_t n, link_frame_t *out)
{
    const uint8_t *body = frame + LINK_HEADER_LEN;
    size_t body_len, i;
    if (n < LINK_MIN_FRAME)
        return RX_SHORT;
    if (n > LINK_MAX_FRAME)
        return RX_OVERSIZE;
    if (link_crc16(frame, n - LINK_CRC_LEN) != get_u16(frame + n - LINK_CRC_LEN))
        return RX_CRC;
    if (frame[0] != LINK_VERSION)
        return RX_VERSION;
    if (!known_type(frame[1]))
        return RX_TYPE;
    body_len = n - LINK_MIN_FRAME;
    if (!body_ok(frame[1], body, body_len))
        return RX_LENGTH;
    memset(out, 0, sizeof *out);
    out->type = frame[1];
    out->seq = get_u16(frame + 2);
    if (out->type == LINK_TARGET) {
        out->count = body[0];
        for (i = 0; i < out->count; i++)
            out->positions[i] = (int16_t)get_u16(body + 1 + 2 * i);
    } else if (out->type == LINK_ARM || out->type == LINK_HOME) {
        out->name_len = body[0];
        memcpy(out->name, body + 1, out->name_len);
    } else if (out->type == LINK_CONFIG) {
        out->key = body[0];
        out->index = body[1];
        out->value = (int32_t)((uint32_t)get_u16(body + 2) | ((uint32_t)get_u16(body + 4) << 16));
    }
    return RX_FRAME;
}

void link_rx_init(link_rx_t *rx) { memset(rx, 0, sizeof *rx); }

link_rx_result_t link_rx_byte(link_rx_t *rx, uint8_t byte, link_frame_t *out)
{
    size_t n;
    if (byte != 0) {
        if (rx->discarding)
            return RX_NONE;
        if (rx->len < LINK_MAX_ENCODED) {
            rx->buf[rx->len++] = byte;
            return RX_NONE;
        }
        rx->discarding = 1;
        rx->len = 0;
        return RX_OVERSIZE;
    }
    if (rx->discarding) {
        rx->discarding = 0;
        return RX_NONE;
    }
    if (rx->len == 0)
        return RX_NONE; /* idle or resync zeros */
    n = link_cobs_decode(rx->buf, rx->len, rx->buf);
    rx->len = 0;
    if (n == SIZE_MAX)
        return RX_COBS;
    return link_parse(rx->buf, n, out);
}

size_t link_encode(uint8_t type, uint16_t seq, const uint8_t *body, size_t body_len, uint8_t *out)
{
    uint8_t frame[LINK_MAX_FRAME];
    size_t n, w;
    if (body_len > LINK_MAX_FRAME - LINK_MIN_FRAME)
        return 0;
    frame[0] = LINK_VERSION;
    frame[1] = type;
    link_put_u16(frame + 2, seq);
    if (body_len)
        memcpy(frame + LINK_HEADER_LEN, body, body_len);
    n = LINK_HEADER_LEN + body_len;
    link_put_u16(frame + n, link_crc16(frame, n));
    w = link_cobs_encode(frame, n + LINK_CRC_LEN, out);
    out[w] = 0;
    return w + 1;
}

size_t link_encode_hello_reply(uint16_t seq, const link_hello_reply_t *m, uint8_t *out)
{
    uint8_t body[9 + LINK_MAX_NAME], *p = body;
    size_t name_len = strlen(m->device);
    if (name_len < 1 || name_len > LINK_MAX_NAME)
        return 0;
    *p++ = m->fw_major;
    *p++ = m->fw_minor;
    *p++ = m->profile;
    *p++ = m->actuators;
    p = link_put_u16(p, m->period_us);
    p = link_put_u16(p, m->heartbeat_ms);
    *p++ = (uint8_t)name_len;
    memcpy(p, m->device, name_len);
    return link_encode(LINK_HELLO_REPLY, seq, body, (size_t)(p - body) + name_len, out);
}

size_t link_encode_status(uint16_t seq, const link_status_t *m, uint8_t *out)
{
    uint8_t body[7], *p = body;
    p = link_put_u16(p, m->ack_seq);
    *p++ = m->ack_type;
    *p++ = m->result;
    *p++ = m->state;
    link_put_u16(p, m->faults);
    return link_encode(LINK_STATUS, seq, body, sizeof body, out);
}

size_t link_encode_telemetry(uint16_t seq, const link_telemetry_t *m, uint8_t *out)
{
    uint8_t body[10 + 4 * LINK_MAX_ACTUATORS + 2 * C_COUNT], *p = body;
    uint8_t i;
    if (m->count < 1 || m->count > LINK_MAX_ACTUATORS)
        return 0;
    *p++ = m->state;
    *p++ = m->flags;
    p = link_put_u16(p, m->faults);
    p = link_put_u32(p, m->uptime_ms);
    *p++ = m->last_reason;
    *p++ = m->count;
    for (i = 0; i < m->count; i++)
        p = link_put_u16(p, (uint16_t)m->commanded[i]);
    for (i = 0; i < m->count; i++)
        p = link_put_u16(p, (uint16_t)m->measured[i]);
    for (i = 0; i < C_COUNT; i++)
        p = link_put_u16(p, m->counters[i]);
    return link_encode(LINK_TELEMETRY, seq, body, (size_t)(p - body), out);
}

int link_seq_accept(link_seq_t *w, uint16_t seq, uint16_t *gap)
{
    uint16_t ahead = (uint16_t)(seq - w->last);
    if (!w->valid) {
        ahead = 1;
    } else if (ahead == 0 || ahead >= 0x8000u) {
        return 0;
    }
    *gap = (uint16_t)(ahead - 1u);
    w->last = seq;
    w->valid = 1;
    return 1;
}
