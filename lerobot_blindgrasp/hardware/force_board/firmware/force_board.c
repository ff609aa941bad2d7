/*
 * force_board.c: three HX711 load-cell ADCs on an Arduino Nano (ATmega328P, 16 MHz) -> blindgrasp force frames.
 *
 * Plain avr-libc, no Arduino core: the whole board is one loop, a millisecond timer and a polled UART, so every
 * timing rule below can be read from this file. Build and flash: see the Makefile and docs/force_board.md.
 *
 * Frame (little-endian, the host decodes it in lerobot_blindgrasp/hardware/force_board/frame_codec.py):
 *   A5 5A | LEN = 15 | SEQ uint16 | COUNTS int32 x 3 (ff, mf, th) | STATUS | CRC-16/CCITT-FALSE over LEN..STATUS
 * The boot frame, the first after every reset (SEQ 0), carries one more byte after STATUS, the reset cause (MCUSR:
 * power-on, reset pin, brown-out, watchdog), and LEN = 16: the host tells a board that restarted from a replay.
 *
 * Recovery without a host: the watchdog resets the board when no frame went out for WDT_RUN (250 ms; 1 s until the
 * first frame, while the chips settle), and a cell with no valid conversion for STUCK_MS is power-cycled through its
 * PD_SCK (high > 60 us powers an HX711 down, low powers it up) every CYCLE_RETRY_MS while its STATUS bit is set.
 * At boot every chip is power-cycled: one caught mid-read by the reset would otherwise shift out the rest of its
 * old conversion as the start of a new one.
 *
 * The rule between conversions: a frame is sent when every HX711 has delivered a new conversion since the last
 * frame, and it carries those samples (the newest one of a chip that converted twice meanwhile) under the next
 * SEQ. Until then nothing is sent: "no new sample yet" is never a frame and never a fault. Each HX711 converts at
 * 80 samples/s (RATE pin high) on its own oscillator, so frames come at the rate of the slowest chip, ~80/s.
 *
 * STATUS bit i reports a real fault of cell i, and nothing else:
 *   - not responding: no valid conversion for NOT_RESPONDING_MS (until the first frame, 500 ms: the chips settle).
 *     DOUT stuck high (unpowered chip, broken wire: the pin's pull-up reads high), or DOUT still low after the
 *     25th clock (no chip driving it). Then a frame is still sent every NOT_RESPONDING_MS, with the fresh samples
 *     of the other cells, the faulty cell's last value and its bit set, so the host can say which cell failed.
 *   - saturated: the conversion is at the ADC's full scale (0x7FFFFF or 0x800000): overload or an open bridge.
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include <stdint.h>
#include <util/atomic.h>
#include <util/crc16.h>
#include <util/delay.h>

#ifndef BAUD
#define BAUD 115200
#endif
#define BAUD_TOL 3 /* 115 200 baud from 16 MHz is 2.1 % fast with U2X, as in every Arduino sketch */
#include <util/setbaud.h>

#define N_CELLS 3
#define ALL_CELLS ((1 << N_CELLS) - 1)
#define NOT_RESPONDING_MS 50 /* 4 conversion periods at 80 samples/s */
#define BOOT_GRACE_MS 500    /* HX711 output settling after power-up: 400 ms at 10/s, 50 ms at 80/s */
#define STUCK_MS 250       /* no valid conversion for 20 periods at 80/s (2.5 at 10/s): stuck, not slow */
#define CYCLE_RETRY_MS 500 /* a power-cycled chip settles in 50 ms at 80/s, 400 ms at 10/s: retry after that */
#define POWER_DOWN_US 100  /* PD_SCK high > 60 us powers an HX711 down */
#define HX711_MAX 0x7FFFFFL
#define HX711_MIN (-0x800000L)

/* Wiring (Arduino Nano pin names): cell i's DOUT on D2, D3, D4 (PD2..PD4), its PD_SCK on D8, D9, D10 (PB0..PB2).
 * DOUT and PD_SCK sit on different ports so that clocking never rewrites the DOUT pins' pull-ups. */
#define DOUT_PIN PIND
#define DOUT_PORT PORTD
#define SCK_PORT PORTB
#define SCK_DDR DDRB
static const uint8_t DOUT_MASK[N_CELLS] = {_BV(PD2), _BV(PD3), _BV(PD4)};
static const uint8_t SCK_MASK[N_CELLS] = {_BV(PB0), _BV(PB1), _BV(PB2)};
#define LED_MASK _BV(PB5) /* D13, the Nano's own LED: blinks ~1/s while frames flow, steady on a fault */

static volatile uint16_t ms_ticks;

/* After a watchdog reset the watchdog stays on at its shortest timeout (~15 ms): turn it off before anything else
 * runs, keeping the reset cause for the boot frame (avr-libc's documented pattern). */
uint8_t reset_cause __attribute__((section(".noinit")));
void early_wdt_off(void) __attribute__((naked, used, section(".init3")));
void early_wdt_off(void) {
    reset_cause = MCUSR;
    MCUSR = 0;
    wdt_disable();
}

ISR(TIMER1_COMPA_vect) { ms_ticks++; }

static uint16_t millis(void) {
    uint16_t t;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { t = ms_ticks; }
    return t;
}

static uint16_t add_saturating(uint16_t a, uint16_t b) {
    uint16_t sum = a + b;
    return sum < a ? 0xFFFF : sum;
}

static void timer_init(void) {
    TCCR1A = 0;
    TCCR1B = _BV(WGM12) | _BV(CS11) | _BV(CS10); /* CTC, clk/64: 250 kHz */
    OCR1A = F_CPU / 64 / 1000 - 1;               /* 1 ms */
    TIMSK1 = _BV(OCIE1A);
}

static void uart_init(void) {
    UBRR0H = UBRRH_VALUE;
    UBRR0L = UBRRL_VALUE;
#if USE_2X
    UCSR0A = _BV(U2X0);
#else
    UCSR0A = 0;
#endif
    UCSR0B = _BV(TXEN0);                 /* transmit only: the host never talks to the board */
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00); /* 8N1 */
}

static void uart_put(uint8_t b) {
    loop_until_bit_is_set(UCSR0A, UDRE0);
    UDR0 = b;
}

/* One conversion of cell i (its DOUT is low): 24 bits MSB first, then a 25th pulse that selects channel A, gain
 * 128, for the next conversion and makes the chip pull DOUT high again. Interrupts stay off for the ~60 us of
 * clocking: PD_SCK held high for more than 60 us powers the HX711 down. Returns 0, and leaves *value alone, when
 * DOUT stayed low after the 25th pulse (the line is held low, not driven by a chip: the bits are not a
 * conversion, and the cell keeps its last valid value). */
static uint8_t hx711_read(uint8_t i, int32_t *value) {
    const uint8_t dout = DOUT_MASK[i], sck = SCK_MASK[i];
    uint32_t v = 0;
    uint8_t ok;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        for (uint8_t b = 0; b < 24; b++) {
            SCK_PORT |= sck;
#if defined(VIOLATE_T2) /* test build: DOUT sampled one cycle (62.5 ns) after the edge, before the bit is valid */
            const uint8_t pins = DOUT_PIN;
            _delay_us(1);
            v = (v << 1) | ((pins & dout) ? 1 : 0);
#elif defined(VIOLATE_T3) /* test build: PD_SCK high for one port write (< 0.2 us) */
            SCK_PORT &= ~sck;
            _delay_us(1);
            v = (v << 1) | ((DOUT_PIN & dout) ? 1 : 0);
#else
            _delay_us(1); /* PD_SCK high >= 0.2 us (T3), data valid 0.1 us after the rising edge (T2) */
            v = (v << 1) | ((DOUT_PIN & dout) ? 1 : 0);
#endif
#ifdef VIOLATE_T4 /* test build: the 25th rising edge one port write after the 24th falling one (< 0.2 us low) */
            if (b == 23) {
                const uint8_t low = SCK_PORT & ~sck, high = low | sck;
                SCK_PORT = low;
                SCK_PORT = high;
                continue;
            }
#endif
#ifndef VIOLATE_T3
            SCK_PORT &= ~sck;
#endif
            _delay_us(1); /* PD_SCK low >= 0.2 us (T4) */
        }
#ifndef VIOLATE_T4
        SCK_PORT |= sck;
#endif
        _delay_us(1);
        SCK_PORT &= ~sck;
        _delay_us(1);
        ok = (DOUT_PIN & dout) != 0;
    }
    if (!ok)
        return 0;
    if (v & 0x800000UL)
        v |= 0xFF000000UL; /* 24-bit two's complement -> int32 */
    *value = (int32_t)v;
    return 1;
}

/* Cell i's HX711 powered down (PD_SCK high > 60 us) and up again: it resets to channel A, gain 128, and settles. */
static void hx711_power_cycle(uint8_t i) {
    SCK_PORT |= SCK_MASK[i];
    _delay_us(POWER_DOWN_US); /* an interrupt only makes it longer */
    SCK_PORT &= ~SCK_MASK[i];
}

/* `boot`: the boot frame, with the reset cause after STATUS. */
static void send_frame(uint16_t seq, const int32_t *counts, uint8_t status, uint8_t boot) {
    uint8_t body[1 + 2 + 4 * N_CELLS + 2]; /* LEN, SEQ, COUNTS, STATUS, reset cause */
    uint8_t n = 0;
    body[n++] = 2 + 4 * N_CELLS + 1 + (boot ? 1 : 0); /* LEN: SEQ..the last body byte */
    body[n++] = seq & 0xFF;
    body[n++] = seq >> 8;
    for (uint8_t i = 0; i < N_CELLS; i++) {
        uint32_t c = (uint32_t)counts[i];
        for (uint8_t k = 0; k < 4; k++)
            body[n++] = (c >> (8 * k)) & 0xFF;
    }
    body[n++] = status;
    if (boot)
        body[n++] = reset_cause;
    uint16_t crc = 0xFFFF; /* CRC-16/CCITT-FALSE: the xmodem update (poly 0x1021, MSB first) from 0xFFFF */
    uart_put(0xA5);
    uart_put(0x5A);
    for (uint8_t k = 0; k < n; k++) {
        crc = _crc_xmodem_update(crc, body[k]);
        uart_put(body[k]);
    }
    uart_put(crc & 0xFF);
    uart_put(crc >> 8);
}

/* One pass over the cells: read each that has a conversion ready; returns the cells that are late (no valid
 * conversion for NOT_RESPONDING_MS, BOOT_GRACE_MS while booting) and sets the saturated ones. A cell stuck for
 * STUCK_MS is power-cycled, again every CYCLE_RETRY_MS while it stays stuck. */
static uint8_t poll_cells(int32_t *counts, uint16_t *age_ms, uint16_t *cycle_ms, uint16_t dt, uint8_t booted,
                          uint8_t *fresh, uint8_t *saturated) {
    uint8_t late = 0;
#ifdef VIOLATE_T1 /* test build: every cell clocked when cell 0 has a conversion, ready or not (DOUT still high) */
    const uint8_t first_ready = !(DOUT_PIN & DOUT_MASK[0]);
#endif
    for (uint8_t i = 0; i < N_CELLS; i++) {
        age_ms[i] = add_saturating(age_ms[i], dt);
        cycle_ms[i] = add_saturating(cycle_ms[i], dt);
#ifdef VIOLATE_T1
        const uint8_t ready = first_ready;
#else
        const uint8_t ready = !(DOUT_PIN & DOUT_MASK[i]);
#endif
        if (ready && hx711_read(i, &counts[i])) {
            *fresh |= _BV(i);
            age_ms[i] = 0;
        }
        if (age_ms[i] > (booted ? NOT_RESPONDING_MS : BOOT_GRACE_MS))
            late |= _BV(i);
        if (booted && age_ms[i] >= STUCK_MS && cycle_ms[i] >= CYCLE_RETRY_MS) {
            hx711_power_cycle(i);
            cycle_ms[i] = 0;
        }
        if (counts[i] == HX711_MAX || counts[i] == HX711_MIN)
            *saturated |= _BV(i);
    }
    return late;
}

int main(void) {
    SCK_DDR |= _BV(PB0) | _BV(PB1) | _BV(PB2) | LED_MASK;
    DOUT_PORT |= _BV(PD2) | _BV(PD3) | _BV(PD4); /* pull-ups: a DOUT wire that came off reads "not ready" */
    for (uint8_t i = 0; i < N_CELLS; i++)
        hx711_power_cycle(i); /* every chip from a known state: PD_SCK low, they power up and settle */
    uart_init();
    timer_init();
    set_sleep_mode(SLEEP_MODE_IDLE);
    wdt_enable(WDTO_1S); /* until the first frame: the chips settle, and a dead one is reported after 500 ms */
    sei();

    int32_t counts[N_CELLS] = {0, 0, 0};
    uint16_t age_ms[N_CELLS] = {0, 0, 0};   /* since the cell's last valid conversion, saturating */
    uint16_t cycle_ms[N_CELLS] = {0, 0, 0}; /* since the cell's last power cycle, saturating */
    uint8_t fresh = 0, booted = 0, frames = 0;
    uint16_t seq = 0, last_tick = millis(), since_frame = 0;
    for (;;) {
        uint16_t now = millis(), dt = now - last_tick;
        last_tick = now;
        if (now >= BOOT_GRACE_MS)
            booted = 1;
#ifdef HANG_ONCE_MS /* test build: the loop hangs once, HANG_ONCE_MS after a reset that was not the watchdog's */
        if (!(reset_cause & _BV(WDRF)) && now >= HANG_ONCE_MS)
            for (;;) {
            }
#endif
        since_frame = add_saturating(since_frame, dt);
        uint8_t saturated = 0;
        uint8_t late = poll_cells(counts, age_ms, cycle_ms, dt, booted, &fresh, &saturated);
        if (fresh == ALL_CELLS || (late && since_frame >= NOT_RESPONDING_MS)) {
            uint8_t status = late | (saturated & fresh);
            send_frame(seq, counts, status, seq == 0);
            if (seq++ == 0) {
                booted = 1;             /* every chip converted (or BOOT_GRACE_MS passed): settled */
                wdt_enable(WDTO_250MS); /* from now on a frame goes out at least every NOT_RESPONDING_MS */
            }
            wdt_reset();                /* progress: a frame went out */
            fresh = 0;
            since_frame = 0;
            if (status)
                SCK_PORT |= LED_MASK;
            else if (++frames % 40 == 0)
                SCK_PORT ^= LED_MASK;
        }
        /* Idle until the next millisecond tick (HX711 data stays valid for a whole conversion period). */
        cli();
        if (millis() == now) {
            sleep_enable();
            sei();
            sleep_cpu();
            sleep_disable();
        }
        sei();
    }
}
