/*
 * hx711_sim.c: the force board in simavr. Runs the firmware's Intel HEX image on an emulated ATmega328P at 16 MHz,
 * with three emulated HX711 chips on its pins and its UART on a pseudo-terminal, paced to the wall clock.
 *
 *   hx711_sim FIRMWARE.hex [SPS]      prints "pty /dev/pts/N" on stdout once the terminal exists
 *
 * Each HX711 follows its datasheet's serial interface: a conversion every 1/SPS s (80 by default, each chip on its
 * own slightly different oscillator) pulls DOUT low; each PD_SCK rising edge shifts out one bit, MSB first; the
 * 25th pulse pulls DOUT high and selects channel A gain 128 for the next conversion (26: B gain 32, 27: A gain 64);
 * PD_SCK high for more than 60 us powers the chip down, and it settles again after PD_SCK returns low.
 * The datasheet's minimum timings are enforced: T1, DOUT falling edge to PD_SCK rising >= 0.1 us (a rising edge
 * while DOUT is high, on a chip with no conversion ready, breaks it too); T2, the bit shifted out is valid 0.1 us
 * after the rising edge (DOUT changes only then, so a firmware that samples earlier reads the previous bit); T3,
 * PD_SCK high >= 0.2 us (and <= 50 us unless it means to power the chip down, > 60 us); T4, PD_SCK low >= 0.2 us.
 * Each violation is counted per chip and reported on exit, and the exit status is then 3.
 *
 * Commands on stdin, one per line (what the load cells feel, and faults):
 *   counts C0 C1 C2     the channel-A counts at gain 128 each cell produces (the ADC clamps them to 24 bits)
 *   noise N             uniform noise of +-N counts on every conversion (a real bridge never repeats exactly)
 *   dead I / alive I    chip I stops converting (DOUT stays high: unpowered chip, broken wire) / recovers
 *   stuck I             chip I's DOUT line held low (shorted to GND): every read clocks out zeros and DOUT stays
 *                       low after the 25th pulse; `alive I` releases it
 *   hang I              chip I locks up (stops converting, DOUT high) until it is powered down and up through
 *                       PD_SCK, as a chip wedged by a glitch; `alive I` releases it too
 *   reset               the ATmega's reset pin pulled (MCUSR EXTRF), as a USB glitch or the DTR line does
 *   quit
 * On exit it reports per chip the conversions made, those read, and reads with another pulse count than 25.
 *
 * The pseudo-terminal is made here rather than with simavr's uart_pty part: that part also creates a fixed
 * /tmp/simavr-uart0 link, which collides between runs in parallel, and hides the file descriptor from the pacing.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "avr_ioport.h"
#include "avr_uart.h"
#include "sim_avr.h"
#include "sim_cycle_timers.h"
#include "sim_hex.h"
#include "sim_irq.h"

#define N_CHIPS 3
#define F_CPU 16000000UL
#define POWER_DOWN_US 60
#define CYCLES_PER_US (F_CPU / 1000000)
/* Datasheet minimums in cycles, rounded up: T1 and T2 0.1 us, T3 and T4 0.2 us; T3 at most 50 us. */
#define T1_CYCLES 2
#define T2_CYCLES 2
#define T3_CYCLES 4
#define T4_CYCLES 4
#define T3_MAX_CYCLES (50 * CYCLES_PER_US)
static const int DOUT_PIN[N_CHIPS] = {2, 3, 4};  /* PORTD: Nano D2, D3, D4 */
static const int SCK_PIN[N_CHIPS] = {0, 1, 2};   /* PORTB: Nano D8, D9, D10 */
static const double SKEW[N_CHIPS] = {0.0, 0.004, -0.003}; /* independent RC oscillators */

typedef struct {
    int index;
    avr_t *avr;
    avr_irq_t *dout;
    int64_t input;          /* counts the bridge produces now (channel A, gain 128), before the ADC's clamp */
    uint32_t data;          /* the conversion being shifted out, 24 bits */
    int ready, pulses, dead, stuck, hung, sck_high, early_rise;
    int gain_pulses;        /* pulse count of the last read: the gain of the next conversion */
    uint32_t level, pending; /* DOUT as driven now; the bit that becomes valid T2 after the rising edge */
    avr_cycle_count_t period, sck_rise, sck_fall, dout_fall;
    long conversions, reads, bad_reads, powered_down;
    long t1, t3, t3_max, t4; /* timing violations */
} hx711_t;

static hx711_t chips[N_CHIPS];
static int32_t noise_counts;
static uint32_t rng = 2463534242u;
static int pty_master = -1;
static long avr_resets;
static uint32_t settle_us = 50000; /* output settling time: 50 ms at 80 samples/s, 400 ms at 10/s */

static int32_t noise(void) {
    rng ^= rng << 13;
    rng ^= rng >> 17;
    rng ^= rng << 5;
    return noise_counts ? (int32_t)(rng % (2u * noise_counts + 1)) - noise_counts : 0;
}

/* What the pin reads: the chip's output, unless something holds the line low. */
static void drive_dout(hx711_t *c, uint32_t level) {
    uint32_t pin = c->stuck ? 0 : level;
    if (!pin && c->level)
        c->dout_fall = c->avr->cycle;
    c->level = pin;
    avr_raise_irq(c->dout, pin);
}

/* The bit shifted out by a rising edge, T2 after it. */
static avr_cycle_count_t bit_valid(avr_t *avr, avr_cycle_count_t when, void *param) {
    hx711_t *c = param;
    (void)avr, (void)when;
    drive_dout(c, c->pending);
    return 0;
}

static int32_t clamp24(int64_t v) { return v > 0x7FFFFF ? 0x7FFFFF : v < -0x800000 ? -0x800000 : (int32_t)v; }

/* The chip's conversion clock. A read in progress (1..24 pulses) keeps its data: this conversion is skipped. */
static avr_cycle_count_t convert(avr_t *avr, avr_cycle_count_t when, void *param) {
    hx711_t *c = param;
    (void)avr;
    if (c->pulses > 0 && c->pulses < 25)
        return when + c->period;
    if (c->pulses) { /* the last read is over: its pulse count sets this conversion's channel and gain */
        c->reads++;
        c->bad_reads += c->pulses != 25;
        c->gain_pulses = c->pulses > 27 ? 25 : c->pulses;
    }
    c->pulses = 0;
    c->ready = 0;
    if (!c->dead && !c->hung) {
        int64_t v = c->input + noise();
        if (c->gain_pulses == 26)
            v = noise(); /* channel B: nothing is wired to it */
        else if (c->gain_pulses == 27)
            v /= 2; /* channel A at gain 64 */
        c->data = (uint32_t)clamp24(v) & 0xFFFFFF;
        c->ready = 1;
        c->conversions++;
    }
    drive_dout(c, !c->ready);
    return when + c->period;
}

static void power_down(hx711_t *c) {
    /* It powered down while PD_SCK was high; going low it resets to gain 128, a lock-up clears, and it settles. */
    c->powered_down++;
    c->ready = c->pulses = c->hung = 0;
    c->gain_pulses = 25;
    avr_cycle_timer_cancel(c->avr, bit_valid, c);
    drive_dout(c, 1);
    avr_cycle_timer_cancel(c->avr, convert, c);
    avr_cycle_timer_register_usec(c->avr, settle_us, convert, c);
}

static void sck_rising(hx711_t *c) {
    avr_cycle_count_t now = c->avr->cycle;
    c->sck_high = 1;
    c->sck_rise = now;
    if (c->sck_fall && now - c->sck_fall < T4_CYCLES)
        c->t4++;
    /* A read begun before DOUT fell, or too soon after (after the 25th-27th pulse the next read waits for DOUT to
     * fall again); judged at the falling edge, since a power-down is no read. */
    c->early_rise = (c->pulses == 0 || c->pulses >= 27) && (c->level || now - c->dout_fall < T1_CYCLES);
    if (!c->ready)
        return;
    c->pulses++;
    if (c->pulses <= 25) {
        c->pending = c->pulses <= 24 ? (c->data >> (24 - c->pulses)) & 1 : 1;
        avr_cycle_timer_register(c->avr, T2_CYCLES, bit_valid, c);
    }
}

static void sck_changed(struct avr_irq_t *irq, uint32_t value, void *param) {
    hx711_t *c = param;
    (void)irq;
    if (value && !c->sck_high) {
        sck_rising(c);
    } else if (!value && c->sck_high) {
        avr_cycle_count_t high = c->avr->cycle - c->sck_rise;
        c->sck_high = 0;
        c->sck_fall = c->avr->cycle;
        if (high < T3_CYCLES)
            c->t3++;
        if (high > POWER_DOWN_US * CYCLES_PER_US) {
            power_down(c);
            return;
        }
        c->t1 += c->early_rise;
        if (high > T3_MAX_CYCLES)
            c->t3_max++;
    }
}

static void uart_out(struct avr_irq_t *irq, uint32_t value, void *param) {
    uint8_t b = value;
    (void)irq;
    (void)param;
    if (write(pty_master, &b, 1) < 0 && errno != EAGAIN)
        perror("pty write"); /* no reader: a real UART's bytes are lost too */
}

/* After an AVR reset (the watchdog's, or `reset`): simavr cleared every cycle timer, the chips' conversion clocks
 * too, and the pin registers, so PIND no longer shows the chips' DOUT. The chips themselves were not reset: their
 * clocks are re-armed and their DOUT levels driven onto the pins again (toggled, since simavr passes on only a
 * change). The port's reset drove PD_SCK low, which no chip takes for a clock edge. */
static void after_reset(avr_t *avr) {
    avr_resets++;
    for (int i = 0; i < N_CHIPS; i++) {
        hx711_t *c = &chips[i];
        c->sck_high = 0;
        c->sck_fall = 0;
        avr_raise_irq(c->dout, !c->level);
        avr_raise_irq(c->dout, c->level);
        if (!avr_cycle_timer_status(avr, convert, c))
            avr_cycle_timer_register(avr, c->period, convert, c);
    }
}

static int command(const char *line) {
    int i;
    long a, b, c;
    if (sscanf(line, "counts %ld %ld %ld", &a, &b, &c) == 3) {
        chips[0].input = a, chips[1].input = b, chips[2].input = c;
    } else if (sscanf(line, "noise %ld", &a) == 1) {
        noise_counts = a < 0 ? 0 : (int32_t)a;
    } else if (sscanf(line, "dead %d", &i) == 1 && i >= 0 && i < N_CHIPS) {
        chips[i].dead = 1;
    } else if (sscanf(line, "hang %d", &i) == 1 && i >= 0 && i < N_CHIPS) {
        chips[i].hung = 1;
    } else if (strncmp(line, "reset", 5) == 0) {
        avr_reset(chips[0].avr);
        after_reset(chips[0].avr);
        avr_regbit_set(chips[0].avr, chips[0].avr->reset_flags.extrf);
    } else if (sscanf(line, "alive %d", &i) == 1 && i >= 0 && i < N_CHIPS) {
        chips[i].dead = chips[i].stuck = chips[i].hung = 0;
        drive_dout(&chips[i], !chips[i].ready || chips[i].pulses >= 25);
    } else if (sscanf(line, "stuck %d", &i) == 1 && i >= 0 && i < N_CHIPS) {
        chips[i].stuck = 1;
        drive_dout(&chips[i], 0);
    } else if (strncmp(line, "quit", 4) == 0) {
        return 1;
    } else if (line[0] != '\n' && line[0]) {
        fprintf(stderr, "hx711_sim: unknown command: %s", line);
    }
    return 0;
}

/* Reads whole lines from stdin without blocking; returns 1 on quit or end of input. */
static int poll_stdin(void) {
    static char buf[4096];
    static size_t len;
    struct pollfd p = {.fd = 0, .events = POLLIN};
    if (poll(&p, 1, 0) <= 0)
        return 0;
    ssize_t n = read(0, buf + len, sizeof buf - 1 - len);
    if (n <= 0)
        return 1;
    len += n;
    buf[len] = 0;
    char *start = buf, *nl;
    while ((nl = strchr(start, '\n'))) {
        char saved = nl[1];
        nl[1] = 0;
        if (command(start))
            return 1;
        nl[1] = saved;
        start = nl + 1;
    }
    len -= start - buf;
    memmove(buf, start, len);
    return 0;
}

static double now_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

static void no_sleep(avr_t *avr, avr_cycle_count_t how_long) { (void)avr, (void)how_long; }

static int open_pty(void) {
    int slave;
    char name[128];
    if (openpty(&pty_master, &slave, name, NULL, NULL) < 0) {
        perror("openpty");
        return -1;
    }
    struct termios t;
    tcgetattr(slave, &t);
    cfmakeraw(&t);
    tcsetattr(slave, TCSANOW, &t);
    fcntl(pty_master, F_SETFL, fcntl(pty_master, F_GETFL) | O_NONBLOCK);
    /* The slave fd stays open, so writes to the master never fail with EIO between client sessions. */
    printf("pty %s\n", name);
    fflush(stdout);
    return 0;
}

int main(int argc, char **argv) {
    if (argc < 2) {
        fprintf(stderr, "usage: %s FIRMWARE.hex [SPS]\n", argv[0]);
        return 2;
    }
    double sps = argc > 2 ? atof(argv[2]) : 80.0;
    if (sps < 40)
        settle_us = 400000;
    uint32_t size = 0, start = 0;
    uint8_t *code = read_ihex_file(argv[1], &size, &start);
    avr_t *avr = avr_make_mcu_by_name("atmega328p");
    if (!code || !avr || sps <= 0) {
        fprintf(stderr, "hx711_sim: cannot load %s (or bad SPS)\n", argv[1]);
        return 2;
    }
    avr_init(avr);
    avr->frequency = F_CPU;
    avr->sleep = no_sleep; /* pacing below, against the wall clock */
    avr_loadcode(avr, code, size, start);
    avr->pc = start;
    uint32_t flags = 0;
    avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    if (open_pty() < 0)
        return 1;
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out, NULL);
    for (int i = 0; i < N_CHIPS; i++) {
        hx711_t *c = &chips[i];
        c->index = i, c->avr = avr, c->gain_pulses = 25;
        c->period = (avr_cycle_count_t)(F_CPU / (sps * (1.0 + SKEW[i])));
        c->dout = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), DOUT_PIN[i]);
        c->level = 1;
        avr_raise_irq(c->dout, 1);
        avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), SCK_PIN[i]), sck_changed, c);
        avr_cycle_timer_register_usec(avr, settle_us + 1000 * i, convert, c);
    }
    double t0 = now_s();
    avr_cycle_count_t next_check = 0;
    int state = cpu_Running;
    void (*run_normal)(avr_t *) = avr->run;
    while (state != cpu_Done && state != cpu_Crashed) {
        int watchdog_reset = avr->run != run_normal; /* the watchdog fired: this run resets the AVR */
        state = avr_run(avr);
        if (watchdog_reset)
            after_reset(avr);
        if (avr->cycle < next_check)
            continue;
        next_check = avr->cycle + F_CPU / 1000;
        if (poll_stdin())
            break;
        double ahead = (double)avr->cycle / F_CPU - (now_s() - t0);
        if (ahead > 0)
            usleep((useconds_t)(ahead * 1e6));
    }
    double sim_s = (double)avr->cycle / F_CPU, wall_s = now_s() - t0;
    fprintf(stderr, "hx711_sim: %.2f s simulated in %.2f s; state %d; %ld AVR resets\n", sim_s, wall_s, state,
            avr_resets);
    long violations = 0;
    for (int i = 0; i < N_CHIPS; i++) {
        hx711_t *c = &chips[i];
        fprintf(stderr, "hx711_sim: chip %d: %ld conversions, %ld reads, %ld reads not of 25 pulses, %ld power-downs\n",
                i, c->conversions, c->reads, c->bad_reads, c->powered_down);
        if (c->t1 || c->t3 || c->t3_max || c->t4)
            fprintf(stderr, "hx711_sim: chip %d: TIMING VIOLATIONS: T1 %ld, T3 %ld (high < 0.2 us), T3 %ld (high > 50 us), "
                    "T4 %ld\n", i, c->t1, c->t3, c->t3_max, c->t4);
        violations += c->t1 + c->t3 + c->t3_max + c->t4;
    }
    return state == cpu_Crashed ? 1 : violations ? 3 : 0;
}
