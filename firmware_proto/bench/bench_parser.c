/* Parser throughput on mixed valid and corrupt traffic, and the CRC's residual error rate.
 *
 *     build/bench_parser [MEGABYTES] [CORRUPT_FRAMES]
 *
 * Traffic: 6-actuator TARGET frames, a third of them with 1-4 random bytes replaced, and
 * runs of noise. Prints MB/s of link_rx_byte (the parser), of device_receive (parser + seq
 * check + dispatch) and of a baseline in the same run: a loop that only splits the bytes at
 * 0x00 (what any framing must do). Then feeds CORRUPT_FRAMES corrupted frames one by one and
 * counts those accepted although they differ from every frame sent (the undetected errors). */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "device.h"

static uint32_t rng = 2463534242u;
static uint32_t next(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 17;
    rng ^= rng << 5;
    return rng;
}

static double seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static size_t target_frame(uint16_t seq, uint8_t *out)
{
    uint8_t body[13], *p = body + 1;
    int i;
    body[0] = 6;
    for (i = 0; i < 6; i++)
        p = link_put_u16(p, (uint16_t)(500 + next() % 14000));
    return link_encode(LINK_TARGET, seq, body, sizeof body, out);
}

static int emit(void *ctx, const uint8_t *b, size_t n)
{
    (void)ctx;
    (void)b;
    (void)n;
    return 1;
}

int main(int argc, char **argv)
{
    size_t megabytes = argc > 1 ? (size_t)atol(argv[1]) : 32u, size = megabytes << 20, n = 0, i;
    long corrupt_frames = argc > 2 ? atol(argv[2]) : 1000000L, k, undetected = 0, rejected = 0;
    uint8_t *traffic = malloc(size + 64), wire[LINK_MAX_ENCODED + 1];
    uint16_t seq = 0;
    link_rx_t rx;
    link_frame_t f;
    static device_t d;
    double t, parse_s, device_s, base_s;
    unsigned long frames = 0, split = 0, sink = 0;
    if (!traffic)
        return 1;
    while (n < size) {
        uint32_t kind = next() % 6;
        if (kind == 0) { /* noise */
            size_t len = next() % 48;
            for (i = 0; i < len && n < size; i++)
                traffic[n++] = (uint8_t)next();
        } else {
            size_t w = target_frame(seq++, wire);
            if (kind == 1) {
                uint32_t edits = 1 + next() % 4;
                while (edits--)
                    wire[next() % (w - 1)] = (uint8_t)next();
            }
            if (n + w > size)
                break;
            memcpy(traffic + n, wire, w);
            n += w;
        }
    }
    size = n;

    t = seconds();
    for (i = 0; i < size; i++) /* baseline: split at 0x00 */
        if (traffic[i] == 0)
            split++;
        else
            sink += traffic[i];
    base_s = seconds() - t;

    link_rx_init(&rx);
    t = seconds();
    for (i = 0; i < size; i++)
        frames += link_rx_byte(&rx, traffic[i], &f) == RX_FRAME;
    parse_s = seconds() - t;

    device_init(&d, profile_find("platform6"), 0, emit, 0, 0, 0, 0);
    t = seconds();
    device_receive(&d, traffic, size, 0);
    device_s = seconds() - t;

    printf("traffic: %.1f MB, %lu valid frames, %lu packets (sink %lu)\n", (double)size / 1e6, frames, split, sink & 1);
    printf("baseline split at 0x00: %8.1f MB/s\n", (double)size / 1e6 / base_s);
    printf("parser (link_rx_byte):  %8.1f MB/s  (%.2f x baseline time)\n", (double)size / 1e6 / parse_s,
           parse_s / base_s);
    printf("device_receive:         %8.1f MB/s  (%.2f x baseline time)\n", (double)size / 1e6 / device_s,
           device_s / base_s);

    for (k = 0; k < corrupt_frames; k++) { /* residual: corrupted frames that pass every check */
        uint8_t original[LINK_MAX_ENCODED + 1];
        size_t w = target_frame((uint16_t)k, wire), j;
        uint32_t edits = 1 + next() % 4;
        link_rx_result_t r = RX_NONE;
        memcpy(original, wire, w);
        while (edits--)
            wire[next() % (w - 1)] = (uint8_t)next();
        if (memcmp(original, wire, w) == 0) {
            k--;
            continue;
        }
        link_rx_init(&rx);
        for (j = 0; j < w; j++) {
            link_rx_result_t got = link_rx_byte(&rx, wire[j], &f);
            if (got == RX_FRAME)
                undetected++;
            if (got != RX_NONE)
                r = got;
        }
        rejected += r != RX_FRAME;
    }
    printf("corrupted frames (1-4 bytes replaced): %ld, rejected %ld, undetected %ld (%.2e; 2^-16 = %.2e)\n",
           corrupt_frames, rejected, undetected, (double)undetected / (double)(corrupt_frames ? corrupt_frames : 1),
           1.0 / 65536.0);
    free(traffic);
    return 0;
}
