/* The fuzz target without libFuzzer: a seeded random stream of inputs mixing noise, valid
 * frames and corrupted valid frames (a plain random stream would never pass the CRC).
 *
 *     build/fuzz_parser RUNS SEED
 */
#include <stdio.h>
#include <stdlib.h>

#include <string.h>

#include "link.h"
#include "profile.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static uint32_t state;
static uint32_t next(void)
{
    state ^= state << 13;
    state ^= state >> 17;
    state ^= state << 5;
    return state;
}

int main(int argc, char **argv)
{
    unsigned long runs = argc > 1 ? strtoul(argv[1], 0, 10) : 1000000ul, run;
    uint8_t input[1500], body[LINK_MAX_FRAME];
    state = argc > 2 ? (uint32_t)strtoul(argv[2], 0, 10) | 1u : 1u;
    for (run = 0; run < runs; run++) {
        size_t n = 1, k;
        uint16_t seq = (uint16_t)next();
        input[0] = (uint8_t)next();
        if (next() % 2) { /* half the inputs start with a session and an arm */
            const profile_t *p = &PROFILES[input[0] % PROFILE_COUNT];
            body[0] = (uint8_t)strlen(p->name);
            memcpy(body + 1, p->name, body[0]);
            n += link_encode(LINK_HELLO, seq++, body, 0, input + n);
            n += link_encode(LINK_ARM, seq++, body, 1u + body[0], input + n);
        }
        while (n < 1200) {
            uint32_t kind = next() % 8; /* 0: noise, 1: a corrupted frame, else a frame */
            if (kind == 0) { /* noise */
                size_t len = next() % 40;
                for (k = 0; k < len; k++)
                    input[n++] = (uint8_t)next();
            } else { /* a frame of any type, mostly in sequence, maybe corrupted */
                const profile_t *p = &PROFILES[input[0] % PROFILE_COUNT];
                size_t len = next() % 20, w;
                uint8_t type = (uint8_t)(next() % 10 < 9 ? LINK_TARGET : next() % 12);
                for (k = 0; k < len; k++)
                    body[k] = (uint8_t)(next() % 16);
                if ((type == LINK_ARM || type == LINK_HOME) && next() % 2) {
                    len = strlen(p->name);
                    body[0] = (uint8_t)len;
                    memcpy(body + 1, p->name, len++);
                } else if (type == LINK_TARGET && next() % 4) {
                    body[0] = p->actuators;
                    for (k = 0; k < p->actuators; k++)
                        link_put_u16(body + 1 + 2 * k, (uint16_t)(next() % 40000u - 20000u));
                    len = 1u + 2u * p->actuators;
                }
                w = link_encode(type, next() % 8 ? seq++ : (uint16_t)(seq - 1u - next() % 4u), body, len, input + n);
                if (kind == 1 && w)
                    input[n + next() % w] = (uint8_t)next();
                n += w;
            }
        }
        LLVMFuzzerTestOneInput(input, n);
    }
    printf("fuzz_stream: %lu inputs, no crash\n", runs);
    return 0;
}
