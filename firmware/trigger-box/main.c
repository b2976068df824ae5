/*
 * Trigger-box firmware for an ATmega328P at 16 MHz (Arduino Uno / Nano): the box side of
 * docs/trigger-box-protocol.md (protocol 2). docs/trigger-box.md: parts, wiring, flashing.
 *
 * Timers:
 *   Timer1  free-running, F_CPU/8 (0.5 us ticks): the box's clock (extended to 64 bits by its
 *           overflow interrupt) and, through its two compare units, the camera pulse (OC1A, D9)
 *           and the strobe (OC1B, D10). Both edges of both lines are set by the compare hardware.
 *   Timer2  fast PWM at 62.5 kHz on OC2B (D3): the steady light level.
 *   Timer0  1 kHz tick: input sampling and debounce, millisecond clock (report period, host
 *           silence, LED).
 *
 * An `F` line fires from the UART receive interrupt: the line is lexed byte by byte as it
 * arrives, so its '\n' finds the command parsed, and the compare unit is programmed to raise the
 * line FIRE_LEAD_TICKS (4 us) after the timer was read. That compare time is the `A` timestamp.
 * Answers are formatted by the main loop from a queue; output goes through an interrupt-driven
 * ring. The watchdog (120 ms) resets the chip if the main loop stops.
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include <string.h>

#include "config.h"
#include "proto.h"

#define CAM_TICKS ((uint16_t)(CAMERA_PULSE_US * TICKS_PER_US))
#if CAMERA_PULSE_US < 50 || CAMERA_PULSE_US > 30000
#error "CAMERA_PULSE_US must be 50..30000"
#endif

#define COM1A_MASK (_BV(COM1A1) | _BV(COM1A0))
#define COM1B_MASK (_BV(COM1B1) | _BV(COM1B0))
#define COM2B_MASK (_BV(COM2B1) | _BV(COM2B0))

/* ---- Reset cause -------------------------------------------------------------------------- */
/* MCUSR as the chip came out of reset; cleared and the watchdog stopped before main (after a
 * watchdog reset the watchdog stays on at its shortest period until this is done). */
uint8_t reset_flags __attribute__((section(".noinit")));
void early_init(void) __attribute__((naked, used, section(".init3")));
void early_init(void) {
    reset_flags = MCUSR;
    MCUSR = 0;
    wdt_disable();
}

/* ---- Clock -------------------------------------------------------------------------------- */
static volatile uint32_t t1_ovf;

ISR(TIMER1_OVF_vect) { t1_ovf++; }

/* Timer1 ticks since start; interrupts must be off. */
static uint64_t ticks_locked(void) {
    uint16_t t = TCNT1;
    uint32_t o = t1_ovf;
    if ((TIFR1 & _BV(TOV1)) && t < 0x8000)
        o++; /* an overflow not yet counted */
    return ((uint64_t)o << 16) | t;
}

static volatile uint32_t ms_clock;

static uint32_t ms_now(void) {
    uint8_t s = SREG;
    cli();
    uint32_t m = ms_clock;
    SREG = s;
    return m;
}

/* ---- Light -------------------------------------------------------------------------------- */
static uint16_t steady_permille = SAFE_LEVEL_PERMILLE; /* last L (or the safe level) */
static uint16_t flash_permille = SAFE_LEVEL_PERMILLE;  /* last S or L level: an F strobe's */
static uint64_t flash_ticks = CAM_TICKS;               /* last S duration: an F strobe's */

/* The PWM output at `permille` (256 steps; 0 disconnects the pin: low, no 1/256 spike). */
static void light_output(uint16_t permille) {
    uint16_t duty = (uint16_t)(((uint32_t)permille * 16777UL + 32768UL) >> 16); /* 0..256 */
    if (duty == 0) {
        TCCR2A &= (uint8_t)~COM2B_MASK;
    } else {
        OCR2B = (uint8_t)(duty - 1);
        TCCR2A = (TCCR2A & (uint8_t)~COM2B_MASK) | _BV(COM2B1);
    }
}

/* ---- Camera and strobe lines ------------------------------------------------------------- */
enum { LINE_IDLE = 0, LINE_RISE, LINE_HIGH, LINE_HOLD };
static volatile uint8_t cam_state, strobe_state;
static uint64_t strobe_end; /* tick of the strobe's falling edge */

/* Drive OC1A/OC1B low now and leave its compare unit disconnected with its output register
 * cleared (forced compare in clear mode), so that the next connection does not show a stale 1.
 * Interrupts off. */
static void cam_off_now(void) {
    TCCR1A = (TCCR1A & (uint8_t)~COM1A_MASK) | _BV(COM1A1);
    TCCR1C = _BV(FOC1A);
    TCCR1A &= (uint8_t)~COM1A_MASK;
    PORTB &= (uint8_t)~_BV(CAM_BIT);
    TIMSK1 &= (uint8_t)~_BV(OCIE1A);
    cam_state = LINE_IDLE;
}

static void strobe_off_now(void) {
    TCCR1A = (TCCR1A & (uint8_t)~COM1B_MASK) | _BV(COM1B1);
    PORTB &= (uint8_t)~_BV(STROBE_BIT);
    TCCR1C = _BV(FOC1B);
    TCCR1A &= (uint8_t)~COM1B_MASK;
    TIMSK1 &= (uint8_t)~_BV(OCIE1B);
    strobe_state = LINE_IDLE;
    light_output(steady_permille);
}

/* Raise the lines in `mask` (bit 0 camera, bit 1 strobe) at the same timer tick, a few
 * microseconds from now; the strobe stays high `strobe_ticks` at `strobe_permille`. Returns 0
 * and the tick of the rising edge, or ERR_BUSY when a line asked for is still high (its last
 * pulse or flash has not ended). Interrupts off (called from the receive interrupt). */
static uint8_t fire(uint8_t mask, uint16_t strobe_permille, uint64_t strobe_ticks, uint64_t *at) {
    if (((mask & 1) && cam_state != LINE_IDLE) || ((mask & 2) && strobe_state != LINE_IDLE))
        return ERR_BUSY;
    uint8_t enable = 0, com = 0;
    if (mask & 1) {
        enable |= _BV(OCIE1A);
        com |= COM1A_MASK; /* set on compare match */
    }
    if (mask & 2) {
        enable |= _BV(OCIE1B);
        com |= COM1B_MASK;
        light_output(strobe_permille); /* PWM takes it at its next period (<= 16 us) */
    }
    /* A flag left by a match of the old compare value is not cleared here (simavr 1.6 clears
     * every Timer1 flag on any TIFR1 write, the overflow's too, and the clock would lose a
     * period): the compare interrupts ignore a match whose time has not come (reached()). */
    uint16_t t = TCNT1;
    uint16_t edge = t + FIRE_LEAD_TICKS;
    if (mask & 1)
        OCR1A = edge;
    if (mask & 2)
        OCR1B = edge;
    TCCR1A |= com;
    if ((uint16_t)(TCNT1 - t) >= FIRE_LEAD_TICKS - 1) {
        /* Programmed too late to be sure of the edge: never seen, but never a pulse 32 ms late. */
        if (mask & 1)
            cam_off_now();
        if (mask & 2)
            strobe_off_now();
        return ERR_FAULT;
    }
    TIMSK1 |= enable;
    uint32_t o = t1_ovf;
    if ((TIFR1 & _BV(TOV1)) && t < 0x8000)
        o++;
    *at = (((uint64_t)o << 16) | t) + FIRE_LEAD_TICKS;
    if (mask & 1)
        cam_state = LINE_RISE;
    if (mask & 2) {
        strobe_state = LINE_RISE;
        strobe_end = *at + strobe_ticks;
    }
    return 0;
}

/* Whether the timer has reached `ocr` (within half a period): a compare interrupt for a
 * value not yet reached comes from a flag an earlier compare value left, and is ignored. */
static uint8_t reached(uint16_t ocr) { return (uint16_t)(TCNT1 - ocr) < 0x8000; }

/* Camera: the rising edge happened (set on match): the falling one CAM_TICKS later, by the
 * same compare unit in clear mode. Then the fall happened: disconnect. */
ISR(TIMER1_COMPA_vect) {
    if (!reached(OCR1A))
        return;
    if (cam_state == LINE_RISE) {
        /* Clear mode first, then the new compare value (simavr applies the old mode's
         * "opposite at overflow" action when OCR1x is written; on the chip either order works). */
        TCCR1A = (TCCR1A & (uint8_t)~COM1A_MASK) | _BV(COM1A1);
        OCR1A += CAM_TICKS;
        cam_state = LINE_HIGH;
    } else {
        TCCR1A &= (uint8_t)~COM1A_MASK;
        TIMSK1 &= (uint8_t)~_BV(OCIE1A);
        cam_state = LINE_IDLE;
    }
}

/* Strobe: after the rise (or a hold wake-up) arrange the fall at strobe_end: by the compare unit
 * when it is less than one timer period away; held high through the port bit, waking 32768
 * ticks before the end, when it is further; waited for here when it is a few microseconds away. */
ISR(TIMER1_COMPB_vect) {
    if (!reached(OCR1B))
        return;
    if (strobe_state == LINE_HIGH) { /* the compare unit has just cleared the line */
        TCCR1A &= (uint8_t)~COM1B_MASK;
        TIMSK1 &= (uint8_t)~_BV(OCIE1B);
        strobe_state = LINE_IDLE;
        light_output(steady_permille);
        return;
    }
    int64_t rem = (int64_t)(strobe_end - ticks_locked());
    if (rem <= SHORT_TICKS) {
        while ((int64_t)(strobe_end - ticks_locked()) > 0) {
        }
        strobe_off_now();
    } else if (rem < 65000) {
        TCCR1A = (TCCR1A & (uint8_t)~COM1B_MASK) | _BV(COM1B1); /* clear on match */
        OCR1B = (uint16_t)strobe_end;
        PORTB &= (uint8_t)~_BV(STROBE_BIT);
        strobe_state = LINE_HIGH;
    } else if (strobe_state == LINE_RISE) {
        PORTB |= _BV(STROBE_BIT); /* the port holds the line while the unit is disconnected */
        TCCR1A &= (uint8_t)~COM1B_MASK;
        OCR1B = (uint16_t)(strobe_end - 32768);
        strobe_state = LINE_HOLD;
    }
}

/* Fail-safe: camera line low, strobe low, light at the safe level. Interrupts off. */
static void outputs_safe(void) {
    cam_off_now();
    steady_permille = SAFE_LEVEL_PERMILLE;
    flash_permille = SAFE_LEVEL_PERMILLE;
    strobe_off_now();
}

/* ---- Answers ------------------------------------------------------------------------------ */
typedef struct {
    uint8_t kind; /* 'A', 'E', 'V' */
    uint8_t code;
    uint32_t seq;
    uint64_t ticks;
} answer_t;

#define ANSWERS 32 /* the host keeps at most 32 commands unanswered */
static answer_t answers[ANSWERS];
static volatile uint8_t ans_head, ans_tail; /* head: receive interrupt; tail: main loop */
static volatile uint8_t ans_dropped;        /* commands dropped for a full queue: `E 0 3` */

/* ---- Host --------------------------------------------------------------------------------- */
static volatile uint32_t host_last_ms;
static volatile uint8_t host_alive; /* a command within HOST_SILENCE_MS */
static lexer_t lexer;

/* Queue an answer (receive interrupt); a well-formed command, done or busy, shows the host is
 * there. */
static void answer(uint8_t kind, uint8_t code, uint32_t seq, uint64_t ticks) {
    if (code == 0 || code == ERR_BUSY) {
        host_last_ms = ms_clock;
        host_alive = 1;
    }
    answer_t *a = &answers[ans_head];
    a->kind = code ? 'E' : kind;
    a->code = code;
    a->seq = seq;
    a->ticks = ticks;
    ans_head = (uint8_t)((ans_head + 1) % ANSWERS);
}

static uint8_t answers_full(void) { return (uint8_t)((ans_head + 1) % ANSWERS) == ans_tail; }

/* Carry out one command other than a well-formed F (receive interrupt) and queue its answer. */
static void execute(const command_t *c) {
    if (c->kind == CMD_NONE)
        return;
    if (answers_full()) {
        ans_dropped++;
        return;
    }
    uint64_t t = 0;
    uint8_t code = c->err, kind = 'A';
    if (!code) {
        switch (c->kind) {
        case CMD_FIRE: /* not reached: the receive interrupt fires well-formed F lines itself */
            code = fire((uint8_t)c->a, flash_permille, flash_ticks, &t);
            break;
        case CMD_STROBE:
            code = fire(2, (uint16_t)c->a, (uint64_t)c->b * TICKS_PER_US, &t);
            if (!code) {
                flash_permille = (uint16_t)c->a;
                flash_ticks = (uint64_t)c->b * TICKS_PER_US;
            }
            break;
        case CMD_LEVEL:
            steady_permille = (uint16_t)c->a;
            flash_permille = (uint16_t)c->a;
            if (strobe_state == LINE_IDLE)
                light_output(steady_permille);
            t = ticks_locked();
            break;
        case CMD_VERSION:
            kind = 'V';
            t = ticks_locked();
            break;
        default: /* CMD_PING */
            t = ticks_locked();
            break;
        }
    }
    answer(kind, code, c->seq, t);
}

ISR(USART_RX_vect) {
    uint8_t status = UCSR0A;
    uint8_t c = UDR0;
    if (status & (_BV(FE0) | _BV(DOR0) | _BV(UPE0)))
        lexer.bad = 1;
    /* The fast path: the '\n' of a well-formed F line fires before anything else. */
    if (c == '\n' && lx_fire_ready(&lexer) && !answers_full()) {
        uint64_t t = 0;
        uint8_t code = fire((uint8_t)lexer.v[3], flash_permille, flash_ticks, &t);
        answer('A', code, lexer.v[1], t);
        lx_reset(&lexer);
        return;
    }
    if (!lx_push(&lexer, c))
        return;
    command_t cmd;
    lx_finish(&lexer, &cmd);
    execute(&cmd);
}

/* ---- Output ring -------------------------------------------------------------------------- */
static uint8_t tx_buf[256];
static volatile uint8_t tx_head, tx_tail; /* 8-bit indices wrap with the 256-byte ring */

static uint8_t tx_free(void) { return (uint8_t)(tx_tail - tx_head - 1); }

static void tx_write(const char *s, uint8_t n) {
    uint8_t h = tx_head;
    while (n--)
        tx_buf[h++] = (uint8_t)*s++;
    tx_head = h;
    UCSR0B |= _BV(UDRIE0);
}

ISR(USART_UDRE_vect) {
    uint8_t t = tx_tail;
    if (t == tx_head) {
        UCSR0B &= (uint8_t)~_BV(UDRIE0);
        return;
    }
    UDR0 = tx_buf[t];
    tx_tail = (uint8_t)(t + 1);
}

static void tx_text(const char *s) { tx_write(s, (uint8_t)strlen(s)); }

/* ---- Inputs ------------------------------------------------------------------------------- */
static volatile uint8_t inputs;       /* bit 0 e-stop pressed, bit 1 door open (debounced) */
static volatile uint8_t inputs_dirty; /* changed (or first known) since the last report */
static volatile uint8_t inputs_known;
static uint8_t in_cand[2] = {0xFF, 0xFF}, in_count[2];

/* 1 kHz: milliseconds, input sampling and debounce. Open contact = pin high = unsafe. The
 * debounce runs with interrupts on, so that a receive interrupt (an F line's end) waits for this
 * one's entry only; the millisecond count is updated before, as the receive interrupt reads it. */
ISR(TIMER0_COMPA_vect) {
    ms_clock++;
    uint8_t pins = PIND;
    sei();
    uint8_t raw[2] = {(uint8_t)((pins >> ESTOP_BIT) & 1), (uint8_t)((pins >> DOOR_BIT) & 1)};
    uint8_t now = inputs, known = 1;
    for (uint8_t i = 0; i < 2; i++) {
        if (raw[i] != in_cand[i]) {
            in_cand[i] = raw[i];
            in_count[i] = 1;
        } else if (in_count[i] < DEBOUNCE_SAMPLES) {
            in_count[i]++;
        }
        if (in_count[i] >= DEBOUNCE_SAMPLES)
            now = (uint8_t)((now & ~(1u << i)) | (in_cand[i] << i));
        else if (!inputs_known)
            known = 0;
    }
    if (!inputs_known && known) {
        inputs_known = 1;
        inputs_dirty = 1;
    }
    if (now != inputs) {
        inputs = now;
        inputs_dirty = 1;
    }
}

/* ---- Start -------------------------------------------------------------------------------- */
static const char *reset_cause(uint8_t f) {
    if (f & _BV(WDRF))
        return "watchdog";
    if (f & _BV(BORF))
        return "brownout";
    if (f & _BV(EXTRF))
        return "external";
    if (f & _BV(PORF))
        return "power";
    return "unknown"; /* a bootloader may have cleared MCUSR */
}

static void hardware_init(void) {
    /* Outputs low first (they were inputs, held low by the board's pull-downs). */
    PORTB = 0;
    DDRB = _BV(CAM_BIT) | _BV(STROBE_BIT) | _BV(LED_BIT);
    PORTD = _BV(ESTOP_BIT) | _BV(DOOR_BIT); /* pull-ups for the normally-closed contacts */
    DDRD = _BV(LIGHT_BIT);

    /* Timer1: normal mode, clk/8; compare outputs disconnected until a fire. */
    TCCR1A = 0;
    TCCR1B = _BV(CS11);
    TIMSK1 = _BV(TOIE1);

    /* Timer2: fast PWM (mode 3), clk/1: 62.5 kHz; OC2B connected only for a level above 0. */
    TCCR2A = _BV(WGM21) | _BV(WGM20);
    TCCR2B = _BV(CS20);
    light_output(SAFE_LEVEL_PERMILLE);

    /* Timer0: CTC, clk/64, 250 counts: 1 kHz. */
    TCCR0A = _BV(WGM01);
    TCCR0B = _BV(CS01) | _BV(CS00);
    OCR0A = 249;
    TIMSK0 = _BV(OCIE0A);

    /* UART: 115200 8N1 (U2X, UBRR 16). */
    UCSR0A = _BV(U2X0); /* before UBRR0: simavr takes the bit rate from UBRR0 writes */
    UBRR0 = UART_UBRR;
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    UCSR0B = _BV(RXCIE0) | _BV(RXEN0) | _BV(TXEN0);

    set_sleep_mode(SLEEP_MODE_IDLE);
}

int main(void) {
    uint8_t cause = reset_flags;
    hardware_init();
    lx_reset(&lexer);
    sei();
    wdt_enable(WDTO_120MS);

    char line[PROTO_MAX_LINE];
    tx_text("# hitl-trigger-box " FW_VERSION " protocol " PROTOCOL_VERSION " reset=");
    tx_text(reset_cause(cause));
    tx_text("\n");

    uint32_t last_report = 0;
    uint8_t silent_notice = 0;
    for (;;) {
        wdt_reset();
        uint32_t now_ms = ms_now();

        /* Inputs: at once on a change, else every INPUT_REPORT_MS. */
        if (inputs_known && (inputs_dirty || now_ms - last_report >= INPUT_REPORT_MS) &&
            tx_free() >= PROTO_MAX_LINE) {
            cli();
            uint8_t in = inputs;
            inputs_dirty = 0;
            uint64_t t = ticks_locked();
            sei();
            tx_write(line, fmt_inputs(line, t / TICKS_PER_US, in & 1, (in >> 1) & 1));
            last_report = now_ms;
        }

        /* Answers, in the order the commands came. */
        while (ans_tail != ans_head && tx_free() >= PROTO_MAX_LINE) {
            const answer_t *a = &answers[ans_tail];
            uint8_t n = fmt_answer(line, a->kind, a->seq, a->code, a->ticks / TICKS_PER_US,
                                   PROTOCOL_VERSION, FW_VERSION);
            ans_tail = (uint8_t)((ans_tail + 1) % ANSWERS);
            tx_write(line, n);
        }
        if (ans_dropped && tx_free() >= PROTO_MAX_LINE) {
            cli();
            ans_dropped = 0;
            sei();
            tx_text("E 0 3\n");
        }

        /* Host silence: fail-safe once, and say so. The clock is read here, with interrupts
         * off: a command taken since now_ms was read may be stamped later than now_ms. */
        cli();
        if (host_alive && ms_clock - host_last_ms >= HOST_SILENCE_MS) {
            host_alive = 0;
            outputs_safe();
            silent_notice = 1;
        }
        uint8_t alive = host_alive;
        sei();
        if (silent_notice && tx_free() >= PROTO_MAX_LINE) {
            tx_text("# safe host-silent\n");
            silent_notice = 0;
        }

        if (alive || (now_ms / 500) % 2)
            PORTB |= _BV(LED_BIT);
        else
            PORTB &= (uint8_t)~_BV(LED_BIT);

        /* Idle until the next interrupt (the 1 ms tick at the latest). */
        cli();
        if (!inputs_dirty && ans_tail == ans_head) {
            sleep_enable();
            sei();
            sleep_cpu();
            sleep_disable();
        }
        sei();
    }
}
