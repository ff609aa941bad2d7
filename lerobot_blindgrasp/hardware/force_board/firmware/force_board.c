/*
 * force_board.c: three HX711 load-cell ADCs on an Arduino Nano (ATmega328P, 16 MHz) -> blindgrasp force frames.
 *
 * Plain avr-libc, no Arduino core: the whole board is one loop, a millisecond timer and a polled UART, so every
 * timing rule below can be read from this file. Build and flash: see the Makefile and docs/force_board.md.
 *
 * Frame (little-endian, the host decodes it in lerobot_blindgrasp/robots/blindgrasp_gripper/force_sensor.py):
 *   A5 5A | LEN = 15 | SEQ uint16 | COUNTS int32 x 3 (ff, mf, th) | STATUS | CRC-16/CCITT-FALSE over LEN..STATUS
 *
 * The rule between conversions: a frame is sent when every HX711 has delivered a new conversion since the last
 * frame, and it carries those samples (the newest one of a chip that converted twice meanwhile) under the next
 * SEQ. Until then nothing is sent: "no new sample yet" is never a frame and never a fault. Each HX711 converts at
 * 80 samples/s (RATE pin high) on its own oscillator, so frames come at the rate of the slowest chip, ~80/s.
 *
 * STATUS bit i reports a real fault of cell i, and nothing else:
 *   - not responding: no valid conversion for NOT_RESPONDING_MS (500 ms after power-up, while the chips settle).
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
            _delay_us(1); /* PD_SCK high >= 0.2 us, data valid 0.1 us after the rising edge */
            v = (v << 1) | ((DOUT_PIN & dout) ? 1 : 0);
            SCK_PORT &= ~sck;
            _delay_us(1);
        }
        SCK_PORT |= sck;
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

static void send_frame(uint16_t seq, const int32_t *counts, uint8_t status) {
    uint8_t body[1 + 2 + 4 * N_CELLS + 1]; /* LEN, SEQ, COUNTS, STATUS */
    uint8_t n = 0;
    body[n++] = 2 + 4 * N_CELLS + 1; /* LEN: SEQ..STATUS */
    body[n++] = seq & 0xFF;
    body[n++] = seq >> 8;
    for (uint8_t i = 0; i < N_CELLS; i++) {
        uint32_t c = (uint32_t)counts[i];
        for (uint8_t k = 0; k < 4; k++)
            body[n++] = (c >> (8 * k)) & 0xFF;
    }
    body[n++] = status;
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

int main(void) {
    MCUSR = 0;
    wdt_disable();
    SCK_DDR |= _BV(PB0) | _BV(PB1) | _BV(PB2) | LED_MASK;
    SCK_PORT &= ~(_BV(PB0) | _BV(PB1) | _BV(PB2)); /* PD_SCK low: the chips power up and convert */
    DOUT_PORT |= _BV(PD2) | _BV(PD3) | _BV(PD4);   /* pull-ups: a DOUT wire that came off reads "not ready" */
    uart_init();
    timer_init();
    set_sleep_mode(SLEEP_MODE_IDLE);
    sei();

    int32_t counts[N_CELLS] = {0, 0, 0};
    uint16_t age_ms[N_CELLS] = {0, 0, 0}; /* since the cell's last valid conversion, saturating */
    uint8_t fresh = 0, booted = 0, frames = 0;
    uint16_t seq = 0, last_tick = millis(), since_frame = 0;
    for (;;) {
        uint16_t now = millis(), dt = now - last_tick;
        last_tick = now;
        if (now >= BOOT_GRACE_MS)
            booted = 1;
        since_frame = add_saturating(since_frame, dt);
        uint8_t late = 0, saturated = 0;
        for (uint8_t i = 0; i < N_CELLS; i++) {
            age_ms[i] = add_saturating(age_ms[i], dt);
            if (!(DOUT_PIN & DOUT_MASK[i]) && hx711_read(i, &counts[i])) {
                fresh |= _BV(i);
                age_ms[i] = 0;
            }
            if (age_ms[i] > (booted ? NOT_RESPONDING_MS : BOOT_GRACE_MS))
                late |= _BV(i);
            if (counts[i] == HX711_MAX || counts[i] == HX711_MIN)
                saturated |= _BV(i);
        }
        if (fresh == ALL_CELLS || (late && since_frame >= NOT_RESPONDING_MS)) {
            uint8_t status = late | (saturated & fresh);
            send_frame(seq++, counts, status);
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
