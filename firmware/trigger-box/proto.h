/*
 * The host-to-box line protocol (docs/trigger-box-protocol.md): a lexer that takes one byte at a
 * time (it runs in the UART receive interrupt, so that the `F` line's last byte finds its command
 * already parsed) and the formatting of the box's lines. No I/O, no AVR registers: the same file
 * builds on the host for firmware/box-sim/proto_test.c.
 */
#ifndef TRIGGER_BOX_PROTO_H
#define TRIGGER_BOX_PROTO_H

#include <stdint.h>

#define PROTO_MAX_LINE 64 /* bytes including '\n' */

enum {
    CMD_NONE = 0, /* empty line: ignored, no answer */
    CMD_PING,     /* P <seq> */
    CMD_VERSION,  /* V <seq> */
    CMD_FIRE,     /* F <seq> <tick> <mask> */
    CMD_LEVEL,    /* L <seq> <permille> */
    CMD_STROBE,   /* S <seq> <permille> <duration_us> */
    CMD_UNKNOWN,
};

/* `E` codes. */
enum {
    ERR_SYNTAX = 1,  /* bad syntax or over-long line */
    ERR_UNKNOWN = 2, /* unknown command */
    ERR_BUSY = 3,    /* a line asked for is still high */
    ERR_FAULT = 4,   /* hardware fault */
};

typedef struct {
    uint8_t len;   /* bytes of the line so far, '\n' excluded */
    uint8_t field; /* index of the field being read (0: the command letter) */
    uint8_t flen;  /* bytes of that field so far */
    uint8_t cmd;   /* the command letter, 0 if the first field is not one character */
    uint8_t bad;   /* structural error: double space, byte after '\r', receive error */
    uint8_t badf;  /* bit i: field i holds a byte that is not a digit */
    uint8_t ovf;   /* bit i: field i exceeds its type (u32; the F tick: u64) */
    uint8_t cr;    /* '\r' seen (only allowed right before '\n') */
    uint8_t toolong;
    uint8_t sig;  /* F tick: significant digits so far */
    int8_t cmp;   /* F tick: its digits against 18446744073709551615 (-1 less, 0 equal, 1 more) */
    uint32_t v[4]; /* field values (v[1] seq; v[2], v[3] arguments; the F tick is not kept) */
} lexer_t;

typedef struct {
    uint8_t kind; /* CMD_* */
    uint8_t err;  /* 0, or the code of the `E` to answer with */
    uint32_t seq; /* 0 when the line has no valid seq */
    uint32_t a;   /* L, S: permille; F: mask */
    uint32_t b;   /* S: duration_us */
} command_t;

void lx_reset(lexer_t *lx);
/* Feed one byte; returns 1 when it was '\n' (call lx_finish), else 0. */
uint8_t lx_push(lexer_t *lx, uint8_t c);
/* The line just ended, as a command (kind CMD_NONE, err 0 for an empty line); resets the lexer. */
void lx_finish(lexer_t *lx, command_t *out);

/* Whether the line so far, ended by '\n' now, is a well-formed `F` line (the receive interrupt
 * fires on this before anything else; lx_finish would return the same command without error). */
static inline uint8_t lx_fire_ready(const lexer_t *lx) {
    return lx->cmd == 'F' && lx->field == 3 && lx->flen && !lx->toolong && !lx->bad &&
           !lx->badf && !lx->ovf && lx->v[1] && lx->v[3] >= 1 && lx->v[3] <= 3;
}

/* Decimal digits of v at p; returns the end. */
char *fmt_u32(char *p, uint32_t v);
char *fmt_u64(char *p, uint64_t v);
/* "A seq us\n", "E seq code\n", "V seq us PROTO FW\n": the answer line; returns its length. */
uint8_t fmt_answer(char *buf, uint8_t kind, uint32_t seq, uint8_t code, uint64_t us,
                   const char *proto, const char *fw);
/* "I us estop door\n"; returns its length. */
uint8_t fmt_inputs(char *buf, uint64_t us, uint8_t estop, uint8_t door);

#endif
