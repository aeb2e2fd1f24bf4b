/* The host build: the firmware core on a pseudo-terminal, with simulated actuators.
 *
 *     build/fw_host [--profile platform6|platform3|servo8] [--name NAME] [--link PATH]
 *                   [--trace] [--duration S] [--exit-on-eof] [--tau-ms MS]
 *
 * The HAL below stands in for a board: the link is a pty (its path is printed), the e-stop
 * input and a stuck actuator are set from stdin, the actuators are first order (tau) and
 * rate limited (2x the profile's speed limit), holding still while outputs are off.
 * stdout: one JSON object a line (events: ready, state, park_step, rx with --trace, status,
 * exit); times are CLOCK_MONOTONIC ns, the clock of Python's time.monotonic_ns().
 * stdin: "status", "estop on", "estop off", "stick I", "unstick I", "quit".
 */
#define _XOPEN_SOURCE 700
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "fw.h"
#include "hal.h"

static struct {
    int master, slave;
    int estop;
    int feedback;
    float tau_s;
    float pos[LINK_MAX_ACTUATORS], cmd[LINK_MAX_ACTUATORS];
    int stuck[LINK_MAX_ACTUATORS];
    int enabled;
    uint64_t sim_ns, last_rx_ns;
    const profile_t *profile;
    int trace;
} host;

static volatile sig_atomic_t stop_requested;

static uint64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

/* --- the HAL --- */

uint32_t hal_millis(void) { return (uint32_t)(now_ns() / 1000000u); }

size_t hal_serial_read(uint8_t *buf, size_t cap)
{
    ssize_t n = read(host.master, buf, cap);
    return n > 0 ? (size_t)n : 0u;
}

int hal_serial_write(const uint8_t *bytes, size_t n)
{
    ssize_t w = write(host.master, bytes, n); /* non-blocking: a reader that stops drops frames */
    return w == (ssize_t)n;
}

/* The board's e-stop gate (board/estop_gate.h): "estop on" is the edge interrupt, which
 * cuts the outputs at once and records the opening; no interrupt can come in between the
 * loop's own calls here (stdin is read between polls), so masking is a no-op. */
#define GATE_PIN() (host.estop)
#define GATE_OUTPUTS_OFF() (host.enabled = 0)
#define GATE_OUTPUTS_ON() (host.enabled = 1)
#define GATE_MASK(s) ((s) = 0)
#define GATE_UNMASK(s) ((void)(s))
#define GATE_POINT() ((void)0)
#include "estop_gate.h"

int hal_estop_input(void) { return gate_estop_input(); }

static void simulate(void)
{
    uint64_t t = now_ns();
    float dt = (float)(t - host.sim_ns) * 1e-9f, rate = 2.0f * host.profile->actuator.vmax * dt;
    float pull = 1.0f - expf(-dt / host.tau_s);
    uint8_t i;
    host.sim_ns = t;
    if (!host.enabled)
        return; /* outputs off: the actuators hold (self-locking screws; a servo goes limp) */
    for (i = 0; i < host.profile->actuators; i++) {
        float step = (host.cmd[i] - host.pos[i]) * pull;
        if (host.stuck[i])
            continue;
        host.pos[i] += step > rate ? rate : (step < -rate ? -rate : step);
    }
}

int hal_read_feedback(int16_t *measured, uint8_t n)
{
    uint8_t i;
    simulate();
    for (i = 0; i < n; i++)
        measured[i] = (int16_t)lrintf(host.pos[i]);
    return host.feedback;
}

void hal_write_outputs(const device_t *d)
{
    uint8_t i;
    simulate(); /* up to now under the old command and enable */
    for (i = 0; i < d->profile->actuators; i++)
        host.cmd[i] = d->axis[i].pos;
    gate_outputs(d->outputs_on);
}

/* --- JSON lines --- */

static void print_positions(const char *key, const float *values, int16_t (*get)(const device_t *, uint8_t),
                            const device_t *d)
{
    uint8_t i;
    printf(",\"%s\":[", key);
    for (i = 0; i < d->profile->actuators; i++)
        printf("%s%d", i ? "," : "", values ? (int)lrintf(values[i]) : get(d, i));
    printf("]");
}

static void print_status(const device_t *d)
{
    uint8_t i;
    printf("{\"event\":\"status\",\"t_ns\":%llu,\"state\":\"%s\",\"faults\":%u,\"outputs_on\":%d,\"homed\":%d,"
           "\"estop_input\":%d,\"heartbeat_ms\":%u,\"pwm_hz\":%u",
           (unsigned long long)now_ns(), device_state_name(d->state), d->faults, d->outputs_on, d->homed,
           host.estop, d->heartbeat_ms, d->pwm_hz);
    print_positions("commanded", 0, device_commanded, d);
    print_positions("measured", host.pos, 0, d);
    printf(",\"pulses_us\":[");
    for (i = 0; i < d->profile->actuators; i++)
        printf("%s%u", i ? "," : "", d->outputs_on ? profile_pulse_us(d->profile, d->axis[i].pos) : 0u);
    printf("],\"counters\":{");
    for (i = 0; i < C_COUNT; i++)
        printf("%s\"%s\":%u", i ? "," : "", LINK_COUNTER_NAMES[i], d->counters[i]);
    printf("}}\n");
    fflush(stdout);
}

static void observe(void *ctx, const link_frame_t *f)
{
    uint8_t i;
    (void)ctx;
    host.last_rx_ns = now_ns();
    if (!host.trace)
        return;
    printf("{\"event\":\"rx\",\"t_ns\":%llu,\"seq\":%u,\"type\":%u", (unsigned long long)host.last_rx_ns, f->seq,
           f->type);
    if (f->type == LINK_TARGET) {
        printf(",\"positions\":[");
        for (i = 0; i < f->count; i++)
            printf("%s%d", i ? "," : "", f->positions[i]);
        printf("]");
    } else if (f->type == LINK_ARM || f->type == LINK_HOME) {
        printf(",\"device\":\"%s\"", f->name); /* printable ASCII only reaches a frame here */
    } else if (f->type == LINK_CONFIG) {
        printf(",\"key\":%u,\"index\":%u,\"value\":%ld", f->key, f->index, (long)f->value);
    }
    printf("}\n");
    fflush(stdout);
}

/* --- the pty and the loop --- */

static int open_pty(const char *link_path)
{
    struct termios tio;
    const char *name;
    host.master = posix_openpt(O_RDWR | O_NOCTTY);
    if (host.master < 0 || grantpt(host.master) || unlockpt(host.master) || !(name = ptsname(host.master)))
        return -1;
    host.slave = open(name, O_RDWR | O_NOCTTY); /* held open: the master never sees EIO */
    if (host.slave < 0 || tcgetattr(host.slave, &tio))
        return -1;
    tio.c_iflag &= (tcflag_t) ~(IGNBRK | BRKINT | PARMRK | ISTRIP | INLCR | IGNCR | ICRNL | IXON);
    tio.c_oflag &= (tcflag_t) ~OPOST;
    tio.c_lflag &= (tcflag_t) ~(ECHO | ECHONL | ICANON | ISIG | IEXTEN);
    tio.c_cflag &= (tcflag_t) ~(CSIZE | PARENB);
    tio.c_cflag |= CS8;
    if (tcsetattr(host.slave, TCSANOW, &tio))
        return -1;
    fcntl(host.master, F_SETFL, fcntl(host.master, F_GETFL) | O_NONBLOCK);
    if (link_path) {
        unlink(link_path);
        if (symlink(name, link_path))
            return -1;
    }
    printf("{\"event\":\"ready\",\"port\":\"%s\",\"t_ns\":%llu", name, (unsigned long long)now_ns());
    return 0;
}

/* One stdin line; returns 0 to quit. */
static int command(fw_t *fw, char *line)
{
    int i;
    if (strncmp(line, "status", 6) == 0)
        print_status(&fw->device);
    else if (strncmp(line, "estop on", 8) == 0) {
        simulate();
        host.estop = 1;
        gate_on_edge(); /* the board's interrupt */
    }
    else if (strncmp(line, "estop off", 9) == 0)
        host.estop = 0;
    else if (sscanf(line, "stick %d", &i) == 1 && i >= 0 && i < (int)LINK_MAX_ACTUATORS)
        host.stuck[i] = 1;
    else if (sscanf(line, "unstick %d", &i) == 1 && i >= 0 && i < (int)LINK_MAX_ACTUATORS)
        host.stuck[i] = 0;
    else if (strncmp(line, "quit", 4) == 0)
        return 0;
    else
        fprintf(stderr, "fw_host: unknown command: %s", line);
    return 1;
}

static void on_signal(int sig)
{
    (void)sig;
    stop_requested = 1;
}

static void usage(void)
{
    fprintf(stderr, "usage: fw_host [--profile NAME] [--name DEVICE] [--link PATH] [--trace] [--duration S] "
                    "[--exit-on-eof] [--tau-ms MS] [--no-feedback]\n");
    exit(2);
}

int main(int argc, char **argv)
{
    static fw_t fw;
    const char *profile_name = "platform6", *name = 0, *link_path = 0;
    double duration = 0.0;
    int exit_on_eof = 0, stdin_open = 1, no_feedback = 0, i;
    char line[128];
    size_t line_len = 0;
    uint64_t start;
    uint8_t last_state;
    uint16_t last_parks;
    int stepped;
    host.tau_s = 0.02f;
    for (i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--profile") && i + 1 < argc) profile_name = argv[++i];
        else if (!strcmp(argv[i], "--name") && i + 1 < argc) name = argv[++i];
        else if (!strcmp(argv[i], "--link") && i + 1 < argc) link_path = argv[++i];
        else if (!strcmp(argv[i], "--duration") && i + 1 < argc) duration = atof(argv[++i]);
        else if (!strcmp(argv[i], "--tau-ms") && i + 1 < argc) host.tau_s = (float)atof(argv[++i]) * 1e-3f;
        else if (!strcmp(argv[i], "--trace")) host.trace = 1;
        else if (!strcmp(argv[i], "--exit-on-eof")) exit_on_eof = 1;
        else if (!strcmp(argv[i], "--no-feedback")) no_feedback = 1;
        else usage();
    }
    host.profile = profile_find(profile_name);
    if (!host.profile || host.tau_s <= 0.0f || (name && (strlen(name) < 1 || strlen(name) > LINK_MAX_NAME))) {
        fprintf(stderr, "fw_host: unknown profile %s or bad --name/--tau-ms\n", profile_name);
        return 2;
    }
    host.feedback = host.profile->feedback && !no_feedback;
    for (i = 0; i < host.profile->actuators; i++)
        host.pos[i] = host.cmd[i] = host.profile->actuator.park;
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    signal(SIGPIPE, SIG_IGN);
    if (open_pty(link_path)) {
        perror("fw_host: pty");
        return 1;
    }
    host.sim_ns = start = now_ns();
    fw_init(&fw, host.profile, name ? name : host.profile->name, observe, 0);
    printf(",\"profile\":\"%s\",\"device\":\"%s\",\"actuators\":%u,\"period_ms\":%u,\"heartbeat_ms\":%u}\n",
           host.profile->name, fw.device.name, host.profile->actuators, host.profile->period_ms,
           fw.device.heartbeat_ms);
    fflush(stdout);
    last_state = fw.device.state;
    last_parks = fw.device.parks;
    while (!stop_requested && (duration <= 0.0 || (double)(now_ns() - start) * 1e-9 < duration)) {
        struct pollfd fds[2] = {{host.master, POLLIN, 0}, {0, POLLIN, 0}};
        int wait_ms = (int)fw_ms_until_step(&fw);
        if (poll(fds, stdin_open ? 2 : 1, wait_ms) < 0 && errno != EINTR)
            break;
        if (stdin_open && (fds[1].revents & (POLLIN | POLLHUP))) {
            ssize_t n = read(0, line + line_len, 1);
            if (n <= 0) {
                stdin_open = 0;
                if (exit_on_eof)
                    break;
            } else if (line[line_len] == '\n' || line_len + 2 >= sizeof line) {
                line[line_len + 1] = 0;
                line_len = 0;
                if (!command(&fw, line))
                    break;
            } else {
                line_len++;
            }
        }
        stepped = fw_poll(&fw);
        if (fw.device.state != last_state || (stepped && fw.device.parks != last_parks)) {
            uint64_t t = now_ns();
            if (fw.device.state != last_state) /* a command's change shows at once, a step's after it */
                printf("{\"event\":\"state\",\"t_ns\":%llu,\"from\":\"%s\",\"to\":\"%s\",\"faults\":%u}\n",
                       (unsigned long long)t, device_state_name(last_state), device_state_name(fw.device.state),
                       fw.device.faults | fw.device.pending_faults);
            if (stepped && fw.device.parks != last_parks) { /* this step was the first park step */
                printf("{\"event\":\"park_step\",\"t_ns\":%llu,\"last_rx_t_ns\":%llu,\"deadman\":%d",
                       (unsigned long long)t, (unsigned long long)host.last_rx_ns,
                       ((fw.device.pending_faults | fw.device.faults) & F_LINK_TIMEOUT) != 0);
                print_positions("commanded", 0, device_commanded, &fw.device);
                printf("}\n");
            }
            fflush(stdout);
            last_state = fw.device.state;
            if (stepped)
                last_parks = fw.device.parks;
        }
    }
    printf("{\"event\":\"exit\",\"t_ns\":%llu,\"state\":\"%s\"}\n", (unsigned long long)now_ns(),
           device_state_name(fw.device.state));
    print_status(&fw.device);
    if (link_path)
        unlink(link_path);
    return 0;
}
