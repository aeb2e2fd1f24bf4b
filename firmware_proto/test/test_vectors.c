/* The C codec against test/link_vectors.json, the vectors the Python codec writes.
 *
 *     build/test_vectors test/link_vectors.json
 *
 * Every frame vector: its wire bytes parse to its fields, and its fields encode to its wire
 * bytes. Every bad vector: rejected with the same error kind. The seq and stream vectors:
 * the same verdicts and counts as Python's. The CONFIG ranges (riderlive.platform.link_vocab.
 * CONFIG_RANGES): the device core accepts each edge and refuses one beyond it. */
#include <cjson/cJSON.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "device.h"
#include "link.h"

static size_t unhex(const char *hex, uint8_t *out, size_t cap)
{
    size_t n = strlen(hex) / 2, i;
    if (n > cap)
        return SIZE_MAX;
    for (i = 0; i < n; i++) {
        unsigned v;
        sscanf(hex + 2 * i, "%2x", &v);
        out[i] = (uint8_t)v;
    }
    return n;
}

static cJSON *load(const char *path)
{
    FILE *f = fopen(path, "rb");
    long size;
    char *text;
    cJSON *json;
    if (!f) {
        perror(path);
        exit(2);
    }
    fseek(f, 0, SEEK_END);
    size = ftell(f);
    fseek(f, 0, SEEK_SET);
    text = malloc((size_t)size + 1);
    if (!text || fread(text, 1, (size_t)size, f) != (size_t)size)
        exit(2);
    text[size] = 0;
    fclose(f);
    json = cJSON_Parse(text);
    free(text);
    if (!json) {
        fprintf(stderr, "%s: not JSON\n", path);
        exit(2);
    }
    return json;
}

static int num(const cJSON *obj, const char *key) { return cJSON_GetObjectItemCaseSensitive(obj, key)->valueint; }
static double dnum(const cJSON *obj, const char *key) { return cJSON_GetObjectItemCaseSensitive(obj, key)->valuedouble; }
static const char *str(const cJSON *obj, const char *key) { return cJSON_GetObjectItemCaseSensitive(obj, key)->valuestring; }
static const cJSON *item(const cJSON *obj, const char *key) { return cJSON_GetObjectItemCaseSensitive(obj, key); }

static const char *const ERROR_NAMES[] = {"none", "frame", "cobs", "short", "oversize", "crc", "version", "type", "length"};

/* Feed a whole wire string byte by byte: the last non-NONE result. */
static link_rx_result_t feed(const uint8_t *wire, size_t n, link_frame_t *frame)
{
    link_rx_t rx;
    link_rx_result_t last = RX_NONE;
    size_t i;
    link_rx_init(&rx);
    for (i = 0; i < n; i++) {
        link_rx_result_t r = link_rx_byte(&rx, wire[i], frame);
        if (r != RX_NONE)
            last = r;
    }
    return last;
}

/* Host -> device: parse and compare fields, then rebuild the body and encode. */
static size_t host_frame(const cJSON *v, const link_frame_t *f, uint8_t *out)
{
    const cJSON *fields = item(v, "fields"), *e;
    uint8_t body[LINK_MAX_FRAME], *p = body;
    int i = 0;
    switch (f->type) {
    case LINK_TARGET:
        CHECK_EQ(f->count, cJSON_GetArraySize(item(fields, "positions")));
        *p++ = f->count;
        cJSON_ArrayForEach(e, item(fields, "positions")) {
            CHECK_EQ(f->positions[i], e->valueint);
            p = link_put_u16(p, (uint16_t)e->valueint);
            i++;
        }
        break;
    case LINK_ARM:
    case LINK_HOME:
        CHECK(strcmp(f->name, str(fields, "device")) == 0);
        *p++ = (uint8_t)strlen(str(fields, "device"));
        memcpy(p, str(fields, "device"), strlen(str(fields, "device")));
        p += strlen(str(fields, "device"));
        break;
    case LINK_CONFIG:
        CHECK_EQ(f->key, num(fields, "key"));
        CHECK_EQ(f->index, num(fields, "index"));
        CHECK_EQ(f->value, (long long)dnum(fields, "value"));
        *p++ = f->key;
        *p++ = f->index;
        p = link_put_u32(p, (uint32_t)(int32_t)dnum(fields, "value"));
        break;
    default:
        break;
    }
    return link_encode(f->type, f->seq, body, (size_t)(p - body), out);
}

static void int16_array(const cJSON *arr, int16_t *out)
{
    const cJSON *e;
    int i = 0;
    cJSON_ArrayForEach(e, arr) out[i++] = (int16_t)e->valueint;
}

/* Device -> host: encode from the fields. */
static size_t device_frame(const cJSON *v, uint16_t seq, uint8_t *out)
{
    const cJSON *fields = item(v, "fields"), *e;
    int type = num(v, "type"), i = 0;
    if (type == LINK_HELLO_REPLY) {
        link_hello_reply_t m;
        m.fw_major = (uint8_t)cJSON_GetArrayItem(item(fields, "firmware"), 0)->valueint;
        m.fw_minor = (uint8_t)cJSON_GetArrayItem(item(fields, "firmware"), 1)->valueint;
        m.profile = (uint8_t)num(fields, "profile");
        m.actuators = (uint8_t)num(fields, "actuators");
        m.period_us = (uint16_t)num(fields, "period_us");
        m.heartbeat_ms = (uint16_t)num(fields, "heartbeat_ms");
        m.device = str(fields, "device");
        return link_encode_hello_reply(seq, &m, out);
    }
    if (type == LINK_STATUS) {
        link_status_t m;
        m.ack_seq = (uint16_t)num(fields, "ack_seq");
        m.ack_type = (uint8_t)num(fields, "ack_type");
        m.result = (uint8_t)num(fields, "result");
        m.state = (uint8_t)num(fields, "state");
        m.faults = (uint16_t)num(fields, "faults");
        return link_encode_status(seq, &m, out);
    } else {
        link_telemetry_t m;
        m.state = (uint8_t)num(fields, "state");
        m.flags = (uint8_t)num(fields, "flags");
        m.faults = (uint16_t)num(fields, "faults");
        m.uptime_ms = (uint32_t)dnum(fields, "uptime_ms");
        m.last_reason = (uint8_t)num(fields, "last_reason");
        m.count = (uint8_t)cJSON_GetArraySize(item(fields, "commanded"));
        int16_array(item(fields, "commanded"), m.commanded);
        int16_array(item(fields, "measured"), m.measured);
        cJSON_ArrayForEach(e, item(fields, "counters")) m.counters[i++] = (uint16_t)e->valueint;
        CHECK_EQ(i, C_COUNT);
        return link_encode_telemetry(seq, &m, out);
    }
}

static void frames(const cJSON *root)
{
    const cJSON *v;
    cJSON_ArrayForEach(v, item(root, "frames")) {
        uint8_t wire[256], frame_bytes[256], out[LINK_MAX_ENCODED + 1];
        size_t n = unhex(str(v, "wire"), wire, sizeof wire), m, k;
        link_frame_t f;
        link_rx_result_t r = feed(wire, n, &f);
        CHECK_EQ(r, RX_FRAME);
        if (r != RX_FRAME) {
            fprintf(stderr, "  frame %s: %s\n", str(v, "name"), ERROR_NAMES[r]);
            continue;
        }
        CHECK_EQ(f.type, num(v, "type"));
        CHECK_EQ(f.seq, num(v, "seq"));
        k = unhex(str(v, "frame"), frame_bytes, sizeof frame_bytes);
        CHECK_EQ(link_cobs_decode(wire, n - 1, out), k);
        CHECK(memcmp(out, frame_bytes, k) == 0);
        m = f.type < LINK_HELLO_REPLY ? host_frame(v, &f, out) : device_frame(v, f.seq, out);
        CHECK_EQ(m, n);
        if (m != n || memcmp(out, wire, n) != 0) {
            fprintf(stderr, "  frame %s: encodes differently\n", str(v, "name"));
            check_failures++;
        }
    }
}

static void bad(const cJSON *root)
{
    const cJSON *v;
    cJSON_ArrayForEach(v, item(root, "bad")) {
        uint8_t wire[256];
        link_frame_t f;
        link_rx_result_t r = feed(wire, unhex(str(v, "wire"), wire, sizeof wire), &f);
        if (strcmp(ERROR_NAMES[r], str(v, "error")) != 0) {
            fprintf(stderr, "bad %s: got %s, expected %s\n", str(v, "name"), ERROR_NAMES[r], str(v, "error"));
            check_failures++;
        }
        check_count++;
    }
}

static void seqs(const cJSON *root)
{
    const cJSON *v;
    cJSON_ArrayForEach(v, item(root, "seq")) {
        link_seq_t w = {0, 0};
        int i, n = cJSON_GetArraySize(item(v, "seqs"));
        for (i = 0; i < n; i++) {
            uint16_t gap = 0;
            int ok = link_seq_accept(&w, (uint16_t)cJSON_GetArrayItem(item(v, "seqs"), i)->valueint, &gap);
            CHECK_EQ(ok, cJSON_IsTrue(cJSON_GetArrayItem(item(v, "accepted"), i)));
            CHECK_EQ(ok ? gap : 0, cJSON_GetArrayItem(item(v, "gaps"), i)->valueint);
        }
    }
}

static const cJSON *frame_named(const cJSON *root, const char *name)
{
    const cJSON *v;
    cJSON_ArrayForEach(v, item(root, "frames")) if (strcmp(str(v, "name"), name) == 0) return v;
    return 0;
}

static void stream(const cJSON *root)
{
    const cJSON *s = item(root, "stream"), *expected = item(s, "frames");
    static uint8_t wire[8192];
    size_t n = unhex(str(s, "wire"), wire, sizeof wire), i;
    int counts[9] = {0}, seen = 0, k;
    link_rx_t rx;
    link_frame_t f;
    link_rx_init(&rx);
    for (i = 0; i < n; i++) {
        link_rx_result_t r = link_rx_byte(&rx, wire[i], &f);
        counts[r]++;
        if (r == RX_FRAME) {
            const cJSON *want = frame_named(root, cJSON_GetArrayItem(expected, seen)->valuestring);
            CHECK(want != 0);
            if (want) {
                CHECK_EQ(f.type, num(want, "type"));
                CHECK_EQ(f.seq, num(want, "seq"));
            }
            seen++;
        }
    }
    CHECK_EQ(seen, cJSON_GetArraySize(expected));
    for (k = RX_COBS; k <= RX_LENGTH; k++)
        CHECK_EQ(counts[k], num(item(s, "errors"), ERROR_NAMES[k]));
}

/* --- the CONFIG ranges: each profile's device core accepts both edges of every key's range and
 * refuses one beyond each (OUT_OF_RANGE, counted) --- */

static uint8_t status_result;

static int take_status(void *ctx, const uint8_t *wire, size_t n)
{
    uint8_t frame[LINK_MAX_ENCODED];
    size_t m = link_cobs_decode(wire, n - 1, frame);
    (void)ctx;
    if (m != SIZE_MAX && m > 7 && frame[1] == LINK_STATUS)
        status_result = frame[7];
    return 1;
}

static int configure(device_t *d, uint16_t *seq, int key, long value)
{
    uint8_t body[6] = {(uint8_t)key, 0}, wire[LINK_MAX_ENCODED + 1];
    link_put_u32(body + 2, (uint32_t)value);
    status_result = 0xFF;
    device_receive(d, wire, link_encode(LINK_CONFIG, (*seq)++, body, sizeof body, wire), 0);
    return status_result;
}

static void config_ranges(const cJSON *root)
{
    const cJSON *prof, *range, *enums = item(root, "enums");
    static device_t d;
    int seen = 0;
    cJSON_ArrayForEach(prof, item(root, "config_ranges")) {
        const profile_t *p = 0;
        uint16_t seq = 1, refused;
        uint8_t i;
        for (i = 0; i < PROFILE_COUNT; i++)
            if (PROFILES[i].id == num(item(enums, "profile"), prof->string))
                p = &PROFILES[i];
        CHECK(p != 0);
        if (!p)
            continue;
        seen++;
        device_init(&d, p, 0, take_status, 0, 0, 0, 0);
        CHECK_EQ(cJSON_GetArraySize(prof), K_PWM_HZ); /* every key */
        cJSON_ArrayForEach(range, prof) {
            int key = num(item(enums, "config_key"), range->string);
            long lo = (long)cJSON_GetArrayItem(range, 0)->valuedouble, hi = (long)cJSON_GetArrayItem(range, 1)->valuedouble;
            refused = d.counters[C_REFUSED];
            CHECK_EQ(configure(&d, &seq, key, lo - 1), REASON_OUT_OF_RANGE);
            CHECK_EQ(configure(&d, &seq, key, hi + 1), REASON_OUT_OF_RANGE);
            CHECK_EQ(d.counters[C_REFUSED], refused + 2);
            CHECK_EQ(configure(&d, &seq, key, hi), REASON_OK);
            CHECK_EQ(configure(&d, &seq, key, lo), REASON_OK); /* ends at lo: SOFT_MIN back at its widest */
        }
    }
    CHECK_EQ(seen, PROFILE_COUNT);
}

int main(int argc, char **argv)
{
    cJSON *root = load(argc > 1 ? argv[1] : "test/link_vectors.json");
    const cJSON *v;
    uint8_t data[256], enc[300], dec[300];
    int count_index = 0;
    CHECK_EQ(num(root, "link_version"), LINK_VERSION);
    CHECK_EQ(link_crc16((const uint8_t *)"123456789", 9), 0x29B1);
    CHECK_EQ(num(item(root, "crc"), "check"), 0x29B1);
    cJSON_ArrayForEach(v, item(root, "cobs")) {
        size_t n = unhex(str(v, "data"), data, sizeof data), m = unhex(str(v, "encoded"), dec, sizeof dec);
        CHECK_EQ(link_cobs_encode(data, n, enc), m);
        CHECK(memcmp(enc, dec, m) == 0);
        CHECK_EQ(link_cobs_decode(dec, m, enc), n);
        CHECK(n == 0 || memcmp(enc, data, n) == 0);
    }
    CHECK_EQ(cJSON_GetArraySize(item(item(root, "enums"), "counters")), C_COUNT);
    cJSON_ArrayForEach(v, item(item(root, "enums"), "counters"))
        CHECK(strcmp(v->valuestring, LINK_COUNTER_NAMES[count_index++]) == 0);
    cJSON_ArrayForEach(v, item(item(root, "enums"), "state"))
        CHECK(strcmp(v->string, device_state_name((uint8_t)v->valueint)) == 0);
    CHECK_EQ(num(item(item(root, "enums"), "reason"), "UNKNOWN_KEY"), REASON_UNKNOWN_KEY);
    CHECK_EQ(num(item(item(root, "enums"), "config_key"), "PWM_HZ"), K_PWM_HZ);
    CHECK_EQ(num(item(item(root, "enums"), "fault"), "HOMING_TIMEOUT"), F_HOMING_TIMEOUT);
    CHECK_EQ(num(item(item(root, "enums"), "fault"), "PARK_TIMEOUT"), F_PARK_TIMEOUT);
    CHECK_EQ(num(root, "park_bound_ms"), PARK_BOUND_MS); /* the device's park timeout, as riderlive knows it */
    CHECK_EQ(num(item(item(root, "enums"), "flag"), "LIMITED"), FL_LIMITED);
    CHECK_EQ(num(item(item(root, "enums"), "type"), "TELEMETRY"), LINK_TELEMETRY);
    frames(root);
    bad(root);
    seqs(root);
    stream(root);
    config_ranges(root);
    cJSON_Delete(root);
    return CHECK_DONE("test_vectors");
}
