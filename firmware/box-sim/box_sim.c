/*
 * box-sim: the trigger-box firmware (an ATmega328P ELF) on simavr at 16 MHz, in real time,
 * behind a pseudo-terminal, so that a host (the Rust driver, firmware/box-sim/selfcheck.py, a
 * terminal) talks to it as to the box on USB.
 *
 *   box-sim ELF --link PATH [--trace FILE.csv] [--press-estop-at S] [--release-estop-at S]
 *           [--open-door-at S] [--close-door-at S] [--bounce-us N] [--hang-at S]
 *           [--duration S] [--verbose]
 *
 * - PATH becomes a symlink to the pty's slave; box-sim holds the slave open (raw mode), so the
 *   host may open and close it as often as it likes.
 * - Simulated time follows the wall clock (box-sim sleeps when it is ahead, and reports how far
 *   it ever fell behind); every time in the trace and in the firmware is simulated time.
 * - Host bytes go into the UART one at a time, each one frame after the previous one (simavr's
 *   frame: 11 bit times at the firmware's 117647 baud = 93.5 us) and only once the firmware has
 *   read the previous one. A byte's end (its last stop bit: the instant simavr raises RXC) is
 *   traced as an `rx` row.
 * - The e-stop (PD4) and door (PD5) contacts are normally closed to ground: closed reads 0,
 *   open (pressed / door open) reads 1 through the pull-up. Each change bounces (--bounce-us,
 *   default 1000: the contact changes 5 times in that time and settles at its end).
 * - --trace FILE.csv: `time_us,pin,level`, one row per change, in time order, time in simulated
 *   microseconds since the start (4 decimals; one cycle is 0.0625 us):
 *     camera, strobe   output pin level 0/1 (an output the firmware has not enabled reads 0: the
 *                      board's pull-down)
 *     light            the PWM duty in 1/256 (0 off .. 256 full on)
 *     estop, door      the input contact: 1 open (pressed / door open), 0 closed
 *     rx               a host byte has ended; level is the byte's value (10 = '\n')
 *     tx               the firmware has started sending a byte (wrote UDR0); level its value;
 *                      it ends one frame (93.5 us) later
 *     reset            the chip was reset (level 1): watchdog
 * - --hang-at S: at S the chip jumps into an endless loop with interrupts off (avr-libc's
 *   `__stop_program`), as a firmware hang would; the watchdog has to reset it.
 * - --duration S: stop after S simulated seconds (default: run until signalled).
 * - SIGTERM / SIGINT: flush the trace, remove PATH, exit 0.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <pty.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "avr_ioport.h"
#include "avr_timer.h"
#include "avr_uart.h"
#include "sim_avr.h"
#include "sim_cycle_timers.h"
#include "sim_elf.h"
#include "sim_io.h"

/* The UART's input fifo functions (static inlines; the header only declares the type). */
DEFINE_FIFO(uint16_t, uart_fifo);

#define FREQ 16000000ULL

/* ATmega328P data-space addresses and bits. */
#define R_DDRB 0x24
#define R_PORTB 0x25
#define R_DDRD 0x2A
#define R_PORTD 0x2B
#define R_MCUSR 0x54
#define R_TCCR1A 0x80
#define R_TCCR1C 0x82
#define R_TCCR2A 0xB0
#define R_OCR2B 0xB4
#define R_UCSR0B 0xC1
#define BIT_CAM 1    /* PB1 OC1A */
#define BIT_STROBE 2 /* PB2 OC1B */
#define BIT_LIGHT 3  /* PD3 OC2B */
#define BIT_ESTOP 4  /* PD4 */
#define BIT_DOOR 5   /* PD5 */

static volatile sig_atomic_t stop_requested;
static void on_signal(int sig) {
    (void)sig;
    stop_requested = 1;
}

static avr_t *avr;
static avr_uart_t *uart;
static avr_irq_t *uart_in;
static FILE *trace;
static int verbose;

/* ---- Trace -------------------------------------------------------------------------------- */
static void trace_row(avr_cycle_count_t cycle, const char *pin, int level) {
    if (!trace)
        return;
    fprintf(trace, "%llu.%04u,%s,%d\n", (unsigned long long)(cycle / 16),
            (unsigned)(cycle % 16) * 625u, pin, level);
}

/* ---- Output pins -------------------------------------------------------------------------- */
/* What the pins show: with its compare unit connected (COM bits not 0) a timer pin shows the
 * unit's output register (kept here from the timer's compare IRQs and forced compares), else the
 * PORT bit; an input pin reads 0 (pull-down on the board).
 *
 * simavr 1.6 also drives the compare output at every Timer1 overflow and OCR1x write as in PWM
 * mode ("set on match" clears it, "clear on match" sets it); in normal mode the chip changes it
 * on a compare match only. So a compare IRQ counts only when the unit's interrupt was raised in
 * the same cycle (a match), which is how avr_timer_comp() does it. */
static int oc1[2];                                   /* OC1A, OC1B output registers */
static avr_cycle_count_t match_cycle[2] = {~0ull, ~0ull}; /* last compare match of each unit */
enum { OUT_CAMERA, OUT_STROBE, OUT_LIGHT, OUT_COUNT };
static const char *out_name[OUT_COUNT] = {"camera", "strobe", "light"};
static int out_level[OUT_COUNT] = {-1, -1, -1};

static void outputs_update(void) {
    uint8_t *d = avr->data;
    int lv[OUT_COUNT];
    uint8_t ddrb = d[R_DDRB], portb = d[R_PORTB], t1a = d[R_TCCR1A];
    lv[OUT_CAMERA] =
        (ddrb >> BIT_CAM) & 1 ? (((t1a >> 6) & 3) ? oc1[0] : (portb >> BIT_CAM) & 1) : 0;
    lv[OUT_STROBE] =
        (ddrb >> BIT_STROBE) & 1 ? (((t1a >> 4) & 3) ? oc1[1] : (portb >> BIT_STROBE) & 1) : 0;
    uint8_t ddrd = d[R_DDRD], portd = d[R_PORTD], t2a = d[R_TCCR2A];
    int com2b = (t2a >> 4) & 3;
    if (!((ddrd >> BIT_LIGHT) & 1))
        lv[OUT_LIGHT] = 0;
    else if (com2b == 2)
        lv[OUT_LIGHT] = d[R_OCR2B] + 1;
    else if (com2b == 3)
        lv[OUT_LIGHT] = 255 - d[R_OCR2B];
    else
        lv[OUT_LIGHT] = ((portd >> BIT_LIGHT) & 1) * 256;
    for (int i = 0; i < OUT_COUNT; i++) {
        if (lv[i] != out_level[i]) {
            out_level[i] = lv[i];
            trace_row(avr->cycle, out_name[i], lv[i]);
        }
    }
}

static void on_register(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)value;
    (void)param;
    outputs_update();
}

static void on_compare(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    intptr_t u = (intptr_t)param;
    if (match_cycle[u] != avr->cycle)
        return; /* not a match: simavr's PWM-style action at overflow / OCR write */
    oc1[u] = (int)(value & 1);
    outputs_update();
}

static void on_match(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    if (value)
        match_cycle[(intptr_t)param] = avr->cycle;
}

/* Forced output compare (simavr does not model FOC1A/FOC1B): the unit's register takes what
 * its COM bits say a match would do. */
static void on_tccr1c(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    uint8_t t1a = avr->data[R_TCCR1A];
    for (int u = 0; u < 2; u++) {
        if (!(value & (0x80u >> u)))
            continue;
        int com = (t1a >> (6 - 2 * u)) & 3;
        if (com == 1)
            oc1[u] ^= 1;
        else if (com == 2)
            oc1[u] = 0;
        else if (com == 3)
            oc1[u] = 1;
    }
    outputs_update();
}

/* ---- Input contacts ----------------------------------------------------------------------- */
typedef struct {
    avr_cycle_count_t cycle;
    int pin; /* 0 e-stop, 1 door */
    int level;
} input_event_t;

static input_event_t *events;
static size_t n_events, next_event;
static int contact[2]; /* 1 = open */
static const char *contact_name[2] = {"estop", "door"};
static const int contact_bit[2] = {BIT_ESTOP, BIT_DOOR};

static void contacts_apply(void) {
    avr_ioport_external_t ext = {.name = 'D',
                                 .mask = (1u << BIT_ESTOP) | (1u << BIT_DOOR),
                                 .value = (unsigned)((contact[0] << BIT_ESTOP) |
                                                     (contact[1] << BIT_DOOR))};
    avr_ioctl(avr, AVR_IOCTL_IOPORT_SET_EXTERNAL('D'), &ext);
    for (int i = 0; i < 2; i++)
        avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), contact_bit[i]),
                      (uint32_t)contact[i]);
}

static avr_cycle_count_t on_input_event(struct avr_t *a, avr_cycle_count_t when, void *param) {
    (void)a;
    (void)param;
    while (next_event < n_events && events[next_event].cycle <= when) {
        input_event_t *e = &events[next_event++];
        if (contact[e->pin] != e->level) {
            contact[e->pin] = e->level;
            trace_row(when, contact_name[e->pin], e->level);
        }
    }
    contacts_apply();
    return next_event < n_events ? events[next_event].cycle : 0;
}

static int event_cmp(const void *a, const void *b) {
    const input_event_t *x = a, *y = b;
    return x->cycle < y->cycle ? -1 : x->cycle > y->cycle ? 1 : 0;
}

/* A contact change at `seconds`, bouncing: level, !level, level, !level, level over bounce_us. */
static void add_change(double seconds, int pin, int level, double bounce_us) {
    static const double frac[5] = {0.0, 0.25, 0.5, 0.75, 1.0};
    int n = bounce_us > 0 ? 5 : 1;
    events = realloc(events, (n_events + (size_t)n) * sizeof *events);
    if (!events) {
        perror("box-sim");
        exit(1);
    }
    for (int i = 0; i < n; i++) {
        double t = seconds * 1e6 + (n > 1 ? frac[i] * bounce_us : 0);
        events[n_events++] = (input_event_t){
            .cycle = (avr_cycle_count_t)(t * 16.0), .pin = pin, .level = i % 2 ? !level : level};
    }
}

/* ---- Host link (pty) ---------------------------------------------------------------------- */
static int master_fd = -1, slave_fd = -1;
static uint8_t rxq[1 << 16];
static size_t rxq_head, rxq_tail; /* bytes from the host waiting for the UART */
static uint8_t txq[1 << 16];
static size_t txq_len; /* bytes from the box waiting for the pty */
static int pump_on;
static avr_cycle_count_t rx_end_pending; /* end of the byte last put in the UART, 0: none */
static int rx_byte_pending;
static unsigned long long n_rx, n_tx, n_dropped, n_flushed;
/* Box output nobody reads is dropped once this much waits (as a USB-serial adapter would). */
#define UNREAD_LIMIT 2048

static avr_cycle_count_t rx_pump(struct avr_t *a, avr_cycle_count_t when, void *param) {
    (void)a;
    (void)param;
    if (rx_end_pending && when >= rx_end_pending) {
        trace_row(rx_end_pending, "rx", rx_byte_pending);
        rx_end_pending = 0;
    }
    if (rx_end_pending)
        return rx_end_pending;
    if (rxq_head == rxq_tail) {
        pump_on = 0;
        return 0;
    }
    /* The firmware has not read the last byte yet, or its receiver is off: look again in 1 us. */
    if (!uart_fifo_isempty(&uart->input) || !(avr->data[R_UCSR0B] & (1u << 4)))
        return when + 16;
    uint8_t b = rxq[rxq_tail];
    rxq_tail = (rxq_tail + 1) % sizeof rxq;
    avr_raise_irq(uart_in, b);
    n_rx++;
    rx_end_pending = when + uart->cycles_per_byte; /* simavr raises RXC then */
    rx_byte_pending = b;
    return rx_end_pending;
}

static void pump_start(void) {
    if (!pump_on && rxq_head != rxq_tail) {
        pump_on = 1;
        avr_cycle_timer_register(avr, 1, rx_pump, NULL);
    }
}

static void on_uart_out(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    trace_row(avr->cycle, "tx", (int)(value & 0xFF));
    if (txq_len < sizeof txq)
        txq[txq_len++] = (uint8_t)value;
    else
        n_dropped++;
    n_tx++;
    if (verbose)
        fputc((int)(value & 0xFF), stderr);
}

static void link_service(void) {
    for (;;) {
        size_t room = (rxq_tail + sizeof rxq - rxq_head - 1) % sizeof rxq;
        if (!room)
            break;
        size_t chunk = sizeof rxq - rxq_head;
        if (chunk > room)
            chunk = room;
        ssize_t n = read(master_fd, rxq + rxq_head, chunk);
        if (n <= 0)
            break;
        rxq_head = (rxq_head + (size_t)n) % sizeof rxq;
    }
    pump_start();
    if (txq_len) {
        int unread = 0;
        if (ioctl(slave_fd, FIONREAD, &unread) == 0 && unread > UNREAD_LIMIT) {
            tcflush(slave_fd, TCIFLUSH);
            n_flushed += (unsigned long long)unread;
        }
        ssize_t n = write(master_fd, txq, txq_len);
        if (n > 0) {
            memmove(txq, txq + n, txq_len - (size_t)n);
            txq_len -= (size_t)n;
        } else if (n < 0 && errno == EAGAIN && txq_len > sizeof txq / 2) {
            n_dropped += txq_len;
            txq_len = 0;
        }
    }
}

/* ---- Hang --------------------------------------------------------------------------------- */
static avr_cycle_count_t hang_cycle;
static avr_flashaddr_t hang_pc; /* an `rjmp .-2` (0xCFFF) in the firmware: __stop_program */

static volatile int hang_now;

/* Due: the main loop moves the PC between two instructions (simavr sets the PC after the cycle
 * timers run, so a timer cannot). */
static avr_cycle_count_t on_hang(struct avr_t *a, avr_cycle_count_t when, void *param) {
    (void)a;
    (void)when;
    (void)param;
    hang_now = 1;
    hang_cycle = 0;
    return 0;
}

static void hang_apply(void) {
    hang_now = 0;
    avr->sreg[S_I] = 0;
    avr->pc = hang_pc;
    avr->state = cpu_Running; /* it may have been asleep */
    fprintf(stderr, "box-sim: hanging the chip at %.6f s (pc 0x%04x)\n",
            (double)avr->cycle / (double)FREQ, (unsigned)hang_pc);
}

/* ---- Reset -------------------------------------------------------------------------------- */
static void (*core_reset)(struct avr_t *);

/* After a (watchdog) reset: the compare units' registers are 0 again, the UART lost what it
 * held, the cycle timers are gone: re-arm ours and show the contacts again (PIN was cleared). */
static void on_reset(struct avr_t *a) {
    if (core_reset)
        core_reset(a);
    oc1[0] = oc1[1] = 0;
    trace_row(a->cycle, "reset", 1);
    rx_end_pending = 0;
    pump_on = 0;
    pump_start();
    if (next_event < n_events)
        avr_cycle_timer_register(a, events[next_event].cycle > a->cycle
                                        ? events[next_event].cycle - a->cycle
                                        : 1,
                                 on_input_event, NULL);
    contacts_apply();
    if (hang_cycle)
        avr_cycle_timer_register(a, hang_cycle > a->cycle ? hang_cycle - a->cycle : 1, on_hang,
                                 NULL);
}

/* simavr's messages to stderr: errors (and warnings with --verbose) only. */
static void sim_logger(struct avr_t *a, const int level, const char *format, va_list ap) {
    (void)a;
    if (level <= (verbose ? LOG_WARNING : LOG_ERROR)) {
        fputs("box-sim: simavr: ", stderr);
        vfprintf(stderr, format, ap);
    }
}

static void no_sleep(struct avr_t *a, avr_cycle_count_t how_long) {
    (void)a;
    (void)how_long; /* the main loop keeps time with the wall clock */
}

/* ---- Main --------------------------------------------------------------------------------- */
static uint64_t mono_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

static void usage(void) {
    fprintf(stderr,
            "usage: box-sim ELF --link PATH [--trace FILE.csv] [--press-estop-at S]\n"
            "               [--release-estop-at S] [--open-door-at S] [--close-door-at S]\n"
            "               [--bounce-us N] [--hang-at S] [--duration S] [--verbose]\n");
    exit(2);
}

static double seconds_arg(const char *s) {
    char *end;
    double v = strtod(s, &end);
    if (*end || v < 0) {
        fprintf(stderr, "box-sim: bad time '%s' (seconds)\n", s);
        exit(2);
    }
    return v;
}

int main(int argc, char **argv) {
    const char *elf = NULL, *link_path = NULL, *trace_path = NULL;
    double duration = 0, bounce_us = 1000, hang_at = -1;
    struct {
        double t;
        int pin, level;
    } changes[64];
    int n_changes = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
        int pin = -1, level = 0;
        if (!strcmp(a, "--press-estop-at"))
            pin = 0, level = 1;
        else if (!strcmp(a, "--release-estop-at"))
            pin = 0, level = 0;
        else if (!strcmp(a, "--open-door-at"))
            pin = 1, level = 1;
        else if (!strcmp(a, "--close-door-at"))
            pin = 1, level = 0;
        if (pin >= 0) {
            if (!v || n_changes == 64)
                usage();
            changes[n_changes].t = seconds_arg(v);
            changes[n_changes].pin = pin;
            changes[n_changes++].level = level;
            i++;
        } else if (!strcmp(a, "--link") && v) {
            link_path = v;
            i++;
        } else if (!strcmp(a, "--trace") && v) {
            trace_path = v;
            i++;
        } else if (!strcmp(a, "--duration") && v) {
            duration = seconds_arg(v);
            i++;
        } else if (!strcmp(a, "--hang-at") && v) {
            hang_at = seconds_arg(v);
            i++;
        } else if (!strcmp(a, "--bounce-us") && v) {
            bounce_us = seconds_arg(v);
            i++;
        } else if (!strcmp(a, "--verbose") || !strcmp(a, "-v")) {
            verbose = 1;
        } else if (a[0] == '-' || elf) {
            usage();
        } else {
            elf = a;
        }
    }
    if (!elf || !link_path)
        usage();
    for (int i = 0; i < n_changes; i++)
        add_change(changes[i].t, changes[i].pin, changes[i].level, bounce_us);
    if (n_events)
        qsort(events, n_events, sizeof *events, event_cmp);

    avr_global_logger_set(sim_logger);
    elf_firmware_t fw;
    memset(&fw, 0, sizeof fw);
    if (elf_read_firmware(elf, &fw) != 0) {
        fprintf(stderr, "box-sim: cannot read %s\n", elf);
        return 1;
    }
    avr = avr_make_mcu_by_name("atmega328p");
    if (!avr) {
        fprintf(stderr, "box-sim: simavr has no atmega328p\n");
        return 1;
    }
    avr_init(avr);
    avr->log = verbose ? LOG_WARNING : LOG_ERROR;
    fw.frequency = FREQ;
    strcpy(fw.mmcu, "atmega328p");
    avr_load_firmware(avr, &fw);
    avr->frequency = FREQ;
    avr->sleep = no_sleep;
    core_reset = avr->reset;
    avr->reset = on_reset;
    avr->data[R_MCUSR] = 1; /* PORF: it was just powered on */

    for (avr_io_t *io = avr->io_port; io; io = io->next)
        if (io->kind && !strcmp(io->kind, "uart") && ((avr_uart_t *)io)->name == '0')
            uart = (avr_uart_t *)io;
    if (!uart) {
        fprintf(stderr, "box-sim: no UART0 in simavr's atmega328p\n");
        return 1;
    }
    uint32_t flags = 0;
    avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~(uint32_t)(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    uart_in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                            on_uart_out, NULL);

    if (trace_path) {
        trace = fopen(trace_path, "w");
        if (!trace) {
            perror(trace_path);
            return 1;
        }
        setvbuf(trace, NULL, _IOFBF, 1 << 20);
        fprintf(trace, "time_us,pin,level\n");
    }
    for (intptr_t u = 0; u < 2; u++) {
        /* TIMER1_COMPA_vect is vector 11, TIMER1_COMPB_vect 12 on the ATmega328P. */
        avr_irq_register_notify(avr_get_interrupt_irq(avr, (uint8_t)(11 + u)), on_match,
                                (void *)u);
        avr_irq_register_notify(
            avr_io_getirq(avr, AVR_IOCTL_TIMER_GETIRQ('1'), TIMER_IRQ_OUT_COMP + (int)u),
            on_compare, (void *)u);
    }
    static const avr_io_addr_t watched[] = {R_DDRB, R_PORTB, R_TCCR1A, R_DDRD,
                                            R_PORTD, R_TCCR2A, R_OCR2B};
    for (size_t i = 0; i < sizeof watched / sizeof watched[0]; i++)
        avr_irq_register_notify(avr_iomem_getirq(avr, watched[i], NULL, AVR_IOMEM_IRQ_ALL),
                                on_register, NULL);
    avr_irq_register_notify(avr_iomem_getirq(avr, R_TCCR1C, NULL, AVR_IOMEM_IRQ_ALL), on_tccr1c,
                            NULL);
    outputs_update();
    contacts_apply(); /* both contacts closed */
    for (int i = 0; i < 2; i++)
        trace_row(0, contact_name[i], contact[i]);
    if (n_events)
        avr_cycle_timer_register(avr, events[0].cycle ? events[0].cycle : 1, on_input_event,
                                 NULL);
    if (hang_at >= 0) {
        for (uint32_t pc = 0; pc + 1 < avr->flashend; pc += 2)
            if (avr->flash[pc] == 0xFF && avr->flash[pc + 1] == 0xCF) {
                hang_pc = pc;
                break;
            }
        if (!hang_pc) {
            fprintf(stderr, "box-sim: --hang-at: no endless loop (rjmp .-2) in %s\n", elf);
            return 1;
        }
        hang_cycle = (avr_cycle_count_t)(hang_at * (double)FREQ);
        avr_cycle_timer_register(avr, hang_cycle ? hang_cycle : 1, on_hang, NULL);
    }

    /* The pty: raw, the slave held open by us, PATH a symlink to it. */
    if (openpty(&master_fd, &slave_fd, NULL, NULL, NULL) != 0) {
        perror("box-sim: openpty");
        return 1;
    }
    struct termios tio;
    tcgetattr(slave_fd, &tio);
    cfmakeraw(&tio);
    cfsetspeed(&tio, B115200);
    tcsetattr(slave_fd, TCSANOW, &tio);
    fcntl(master_fd, F_SETFL, fcntl(master_fd, F_GETFL) | O_NONBLOCK);
    const char *slave_name = ttyname(slave_fd);
    struct stat st;
    if (lstat(link_path, &st) == 0) {
        if (!S_ISLNK(st.st_mode)) {
            fprintf(stderr, "box-sim: %s exists and is not a symlink\n", link_path);
            return 1;
        }
        unlink(link_path);
    }
    if (!slave_name || symlink(slave_name, link_path) != 0) {
        perror("box-sim: symlink");
        return 1;
    }

    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);
    fprintf(stderr, "box-sim: %s at 16 MHz on %s (%s)\n", elf, link_path, slave_name);

    uint64_t t0 = mono_ns();
    avr_cycle_count_t c0 = avr->cycle;
    int64_t max_lag_ns = 0;
    int state = cpu_Running;
    while (!stop_requested) {
        for (int i = 0; i < 4000; i++) {
            state = avr_run(avr);
            if (state == cpu_Done || state == cpu_Crashed)
                break;
            if (hang_now)
                hang_apply();
        }
        if (state == cpu_Done || state == cpu_Crashed) {
            fprintf(stderr, "box-sim: the simulated chip stopped (state %d)\n", state);
            break;
        }
        link_service();
        uint64_t sim_ns = (uint64_t)(avr->cycle - c0) * 125 / 2;
        uint64_t wall_ns = mono_ns() - t0;
        if (sim_ns > wall_ns + 200000) {
            uint64_t ahead = sim_ns - wall_ns;
            struct timespec ts = {(time_t)(ahead / 1000000000ull), (long)(ahead % 1000000000ull)};
            nanosleep(&ts, NULL);
        } else if ((int64_t)(wall_ns - sim_ns) > max_lag_ns) {
            max_lag_ns = (int64_t)(wall_ns - sim_ns);
        }
        if (duration > 0 && (double)sim_ns >= duration * 1e9)
            break;
    }
    link_service();
    double sim_s = (double)(avr->cycle - c0) / (double)FREQ;
    double wall_s = (double)(mono_ns() - t0) / 1e9;
    if (trace && fclose(trace) != 0)
        perror("box-sim: trace");
    unlink(link_path);
    fprintf(stderr,
            "box-sim: %.3f s simulated in %.3f s; most behind the wall clock: %.3f ms; "
            "host bytes in %llu, box bytes out %llu (dropped %llu, flushed unread %llu)\n",
            sim_s, wall_s, (double)max_lag_ns / 1e6, n_rx, n_tx, n_dropped, n_flushed);
    return state == cpu_Done || state == cpu_Crashed ? 1 : 0;
}
