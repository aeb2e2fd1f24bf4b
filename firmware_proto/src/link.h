/* The platform link (docs/platform-link.md): CRC-16, COBS, frame validation and encoding.
 *
 * A frame before COBS, little-endian:
 *     version u8 | type u8 | seq u16 | body | crc u16 (CRC-16/IBM-3740 of all before it)
 * On the wire: COBS(frame) then one 0x00. Pure C99, no I/O, no allocation; the same
 * vectors as the Python codec (test/link_vectors.json) pin every byte.
 */
#ifndef LINK_H
#define LINK_H

#include <stddef.h>
#include <stdint.h>

#define LINK_VERSION 1u
#define LINK_HEADER_LEN 4u
#define LINK_CRC_LEN 2u
#define LINK_MIN_FRAME (LINK_HEADER_LEN + LINK_CRC_LEN)
#define LINK_MAX_FRAME 96u
#define LINK_MAX_ENCODED (LINK_MAX_FRAME + 1u) /* one COBS code byte: frames < 254 bytes */
#define LINK_MAX_ACTUATORS 8u
#define LINK_MAX_NAME 16u

typedef enum {
    LINK_HELLO = 0x01,
    LINK_TARGET = 0x02,
    LINK_ARM = 0x03,
    LINK_DISARM = 0x04,
    LINK_HOME = 0x05,
    LINK_PARK = 0x06,
    LINK_ESTOP = 0x07,
    LINK_RESET = 0x08,
    LINK_HEARTBEAT = 0x09,
    LINK_CONFIG = 0x0A,
    LINK_HELLO_REPLY = 0x81,
    LINK_STATUS = 0x82,
    LINK_TELEMETRY = 0x83
} link_type_t;

/* The lifecycle state byte: the names of coord/LIFECYCLE.md, in this order. */
typedef enum {
    ST_DISCONNECTED = 0, ST_CONNECTING, ST_DISARMED, ST_HOMING, ST_SOFT_START,
    ST_RUNNING, ST_PARKING, ST_PARKED, ST_ESTOP, ST_FAULT
} link_state_t;

typedef enum {
    REASON_OK = 0, REASON_NOT_ARMED, REASON_LATCHED, REASON_MOVING, REASON_WRONG_DEVICE, REASON_ESTOP_INPUT,
    REASON_BAD_COUNT, REASON_OUT_OF_RANGE, REASON_UNKNOWN_KEY
} link_reason_t;

enum { /* latched fault bits */
    F_ESTOP_INPUT = 0x0001, F_ESTOP_LINK = 0x0002, F_LINK_TIMEOUT = 0x0004,
    F_FOLLOWING_ERROR = 0x0008, F_HOMING_TIMEOUT = 0x0010, F_LINK_ERRORS = 0x0020,
    F_PARK_TIMEOUT = 0x0040 /* a park not over PARK_BOUND_MS after it began (a starved loop): outputs off */
};
enum { /* live telemetry flags */
    FL_HOMED = 0x01, FL_ESTOP_INPUT = 0x02, FL_OUTPUTS_ON = 0x04, FL_LINK_OK = 0x08, FL_LIMITED = 0x10
};
typedef enum {
    K_HEARTBEAT_TIMEOUT_MS = 1, K_TELEMETRY_PERIOD_MS, K_SOFT_MIN, K_SOFT_MAX,
    K_VELOCITY_LIMIT, K_ACCELERATION_LIMIT, K_PWM_HZ
} link_config_key_t;

/* Counters, in TELEMETRY order (riderlive.platform.link.COUNTERS). */
typedef enum {
    C_RX_OK, C_RX_COBS, C_RX_SHORT, C_RX_OVERSIZE, C_RX_CRC, C_RX_VERSION, C_RX_TYPE,
    C_RX_LENGTH, C_RX_STALE, C_RX_GAP, C_REFUSED, C_CLIPPED, C_LIMITED, C_DEADMAN,
    C_TX_DROPPED, C_COUNT
} link_counter_t;

extern const char *const LINK_COUNTER_NAMES[C_COUNT]; /* "rx_ok", ... as in TELEMETRY */

/* What one packet (the bytes up to a 0x00) turned out to be; the errors name counters. */
typedef enum {
    RX_NONE = 0, RX_FRAME, RX_COBS, RX_SHORT, RX_OVERSIZE, RX_CRC, RX_VERSION, RX_TYPE, RX_LENGTH
} link_rx_result_t;

/* A validated frame. Host -> device bodies are decoded; device -> host frames are only
 * length-checked (a device ignores them). */
typedef struct {
    uint8_t type;
    uint16_t seq;
    uint8_t count;                            /* TARGET */
    int16_t positions[LINK_MAX_ACTUATORS];    /* TARGET, counts */
    uint8_t name_len;                         /* ARM, HOME */
    char name[LINK_MAX_NAME + 1];             /* NUL-terminated */
    uint8_t key, index;                       /* CONFIG */
    int32_t value;
} link_frame_t;

/* Device -> host messages (encoded only by the firmware, decoded by riderlive). */
typedef struct {
    uint8_t fw_major, fw_minor, profile, actuators;
    uint16_t period_us, heartbeat_ms;
    const char *device; /* 1..16 ASCII characters */
} link_hello_reply_t;

typedef struct {
    uint16_t ack_seq;
    uint8_t ack_type, result, state;
    uint16_t faults;
} link_status_t;

typedef struct {
    uint8_t state, flags;
    uint16_t faults;
    uint32_t uptime_ms;
    uint8_t last_reason, count;
    int16_t commanded[LINK_MAX_ACTUATORS], measured[LINK_MAX_ACTUATORS];
    uint16_t counters[C_COUNT];
} link_telemetry_t;

/* The receiver's sequence window: a frame is new if (seq - last) mod 2^16 is 1..32767. */
typedef struct {
    uint16_t last;
    uint8_t valid; /* 0: accept the next seq whatever it is */
} link_seq_t;

/* Byte-at-a-time receiver: COBS packets split at 0x00, decoded and validated. */
typedef struct {
    uint8_t buf[LINK_MAX_ENCODED];
    uint8_t len;
    uint8_t discarding; /* dropping an over-long run up to the next 0x00 */
} link_rx_t;

uint16_t link_crc16(const uint8_t *data, size_t n);
/* COBS; both return the output length, decode returns SIZE_MAX on a malformed packet. */
size_t link_cobs_encode(const uint8_t *in, size_t n, uint8_t *out);
size_t link_cobs_decode(const uint8_t *in, size_t n, uint8_t *out);

/* Validate a frame (before COBS): short, oversize, crc, version, type, length, in that order. */
link_rx_result_t link_parse(const uint8_t *frame, size_t n, link_frame_t *out);
void link_rx_init(link_rx_t *rx);
/* Feed one byte; returns RX_NONE until a packet ends (or overflows). */
link_rx_result_t link_rx_byte(link_rx_t *rx, uint8_t byte, link_frame_t *out);

/* Frame (header + body + CRC), COBS and the trailing 0x00 into out (>= LINK_MAX_ENCODED + 1
 * bytes); returns the wire length, 0 if the body does not fit a frame. */
size_t link_encode(uint8_t type, uint16_t seq, const uint8_t *body, size_t body_len, uint8_t *out);

size_t link_encode_hello_reply(uint16_t seq, const link_hello_reply_t *m, uint8_t *out);
size_t link_encode_status(uint16_t seq, const link_status_t *m, uint8_t *out);
size_t link_encode_telemetry(uint16_t seq, const link_telemetry_t *m, uint8_t *out);

/* 1 and *gap = frames skipped if seq is new (and accept it), 0 if stale (a repeat or older). */
int link_seq_accept(link_seq_t *w, uint16_t seq, uint16_t *gap);

/* Little-endian body writers, for the encoders of device.c and the tests. */
uint8_t *link_put_u16(uint8_t *p, uint16_t v);
uint8_t *link_put_u32(uint8_t *p, uint32_t v);

#endif
