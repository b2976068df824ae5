/* The host-to-box line lexer and the box's line formatting (see proto.h). */
#include "proto.h"

#include <string.h>
#ifdef __AVR__
#include <stdlib.h> /* ultoa: avr-libc's digit loop, much faster than a 32-bit divide per digit */
#endif

static const char U64_MAX_DIGITS[20] = {'1', '8', '4', '4', '6', '7', '4', '4', '0', '7',
                                        '3', '7', '0', '9', '5', '5', '1', '6', '1', '5'};

void lx_reset(lexer_t *lx) { memset(lx, 0, sizeof *lx); }

/* Fields each command has, its letter included. */
static uint8_t fields_of(uint8_t kind) {
    switch (kind) {
    case CMD_PING:
    case CMD_VERSION:
        return 2;
    case CMD_LEVEL:
        return 3;
    case CMD_FIRE:
    case CMD_STROBE:
        return 4;
    default:
        return 0;
    }
}

static uint8_t kind_of(uint8_t letter) {
    switch (letter) {
    case 'P':
        return CMD_PING;
    case 'V':
        return CMD_VERSION;
    case 'F':
        return CMD_FIRE;
    case 'L':
        return CMD_LEVEL;
    case 'S':
        return CMD_STROBE;
    default:
        return CMD_UNKNOWN;
    }
}

/* The F tick is a u64: more than 20 significant digits, or 20 that compare above the largest. */
static void tick_end(lexer_t *lx) {
    if (lx->sig > 20 || (lx->sig == 20 && lx->cmp > 0))
        lx->ovf |= 1u << 2;
}

uint8_t lx_push(lexer_t *lx, uint8_t c) {
    if (c == '\n')
        return 1;
    if (lx->toolong)
        return 0;
    if (++lx->len >= PROTO_MAX_LINE) { /* 63 bytes and the '\n' is the longest line */
        lx->toolong = 1;
        return 0;
    }
    if (lx->cr)
        lx->bad = 1; /* '\r' not at the end */
    if (c == '\r') {
        lx->cr = 1;
        return 0;
    }
    if (c == ' ') {
        if (lx->flen == 0) {
            lx->bad = 1; /* leading or double space */
            return 0;
        }
        if (lx->field == 2 && lx->cmd == 'F')
            tick_end(lx);
        if (lx->field < 4)
            lx->field++;
        lx->flen = 0;
        return 0;
    }
    uint8_t f = lx->field;
    if (f == 0) {
        lx->cmd = lx->flen == 0 ? c : 0;
        lx->flen++;
        if (c < 0x21 || c > 0x7E)
            lx->bad = 1;
        return 0;
    }
    lx->flen++;
    if (c < '0' || c > '9') {
        lx->badf |= 1u << f;
        return 0;
    }
    if (f > 3)
        return 0; /* an extra field: counted, refused at the end */
    uint8_t d = c - '0';
    if (f == 2 && lx->cmd == 'F') {
        if (d == 0 && lx->sig == 0)
            return 0; /* leading zero */
        if (lx->sig < 20 && lx->cmp == 0) {
            char m = U64_MAX_DIGITS[lx->sig];
            if ((char)c < m)
                lx->cmp = -1;
            else if ((char)c > m)
                lx->cmp = 1;
        }
        if (lx->sig < 255)
            lx->sig++;
        return 0;
    }
    uint32_t v = lx->v[f];
    if (v > 429496729UL || (v == 429496729UL && d > 5)) {
        lx->ovf |= 1u << f;
        return 0;
    }
    lx->v[f] = v * 10 + d;
    return 0;
}

void lx_finish(lexer_t *lx, command_t *out) {
    out->kind = CMD_NONE;
    out->err = 0;
    out->seq = 0;
    out->a = 0;
    out->b = 0;
    if (lx->toolong) {
        out->kind = CMD_UNKNOWN;
        out->err = ERR_SYNTAX; /* answered `E 0 1`: its seq cannot be trusted */
        lx_reset(lx);
        return;
    }
    if (lx->len == 0 || (lx->len == 1 && lx->cr)) {
        lx_reset(lx); /* an empty line: a host may send one to end a partial line */
        return;
    }
    uint8_t bad = lx->bad;
    if (lx->flen == 0)
        bad = 1; /* trailing space */
    else if (lx->field == 2 && lx->cmd == 'F')
        tick_end(lx);
    uint8_t nfields = lx->field + 1;
    if (nfields >= 2 && !(lx->badf & 2) && !(lx->ovf & 2) && !(lx->field == 1 && lx->flen == 0))
        out->seq = lx->v[1];
    uint8_t kind = kind_of(lx->cmd);
    out->kind = kind;
    if (kind == CMD_UNKNOWN) {
        out->err = ERR_UNKNOWN;
    } else if (bad || lx->badf || lx->ovf || nfields != fields_of(kind) || out->seq == 0) {
        out->err = ERR_SYNTAX;
    } else if (kind == CMD_FIRE) {
        out->a = lx->v[3];
        if (out->a < 1 || out->a > 3)
            out->err = ERR_SYNTAX;
    } else if (kind == CMD_LEVEL) {
        out->a = lx->v[2];
        if (out->a > 1000)
            out->err = ERR_SYNTAX;
    } else if (kind == CMD_STROBE) {
        out->a = lx->v[2];
        out->b = lx->v[3];
        if (out->a > 1000 || out->b == 0)
            out->err = ERR_SYNTAX;
    }
    lx_reset(lx);
}

char *fmt_u32(char *p, uint32_t v) {
#ifdef __AVR__
    ultoa(v, p, 10);
    return p + strlen(p);
#else
    char tmp[10];
    uint8_t n = 0;
    do {
        tmp[n++] = (char)('0' + v % 10);
        v /= 10;
    } while (v);
    while (n)
        *p++ = tmp[--n];
    return p;
#endif
}

char *fmt_u64(char *p, uint64_t v) {
    if (!(v >> 32))
        return fmt_u32(p, (uint32_t)v);
    /* One 64-bit division, then 32-bit digits: the box's microseconds pass 2^32 after 71 min. */
    uint64_t hi = v / 1000000000UL;
    uint32_t lo = (uint32_t)(v - hi * 1000000000UL);
    p = fmt_u64(p, hi);
    char tmp[11];
    char *e = fmt_u32(tmp, lo);
    uint8_t n = (uint8_t)(e - tmp);
    for (uint8_t i = n; i < 9; i++)
        *p++ = '0';
    memcpy(p, tmp, n);
    return p + n;
}

uint8_t fmt_answer(char *buf, uint8_t kind, uint32_t seq, uint8_t code, uint64_t us,
                   const char *proto, const char *fw) {
    char *p = buf;
    *p++ = (char)kind;
    *p++ = ' ';
    p = fmt_u32(p, seq);
    *p++ = ' ';
    if (kind == 'E') {
        p = fmt_u32(p, code);
    } else {
        p = fmt_u64(p, us);
        if (kind == 'V') {
            *p++ = ' ';
            size_t n = strlen(proto);
            memcpy(p, proto, n);
            p += n;
            *p++ = ' ';
            n = strlen(fw);
            memcpy(p, fw, n);
            p += n;
        }
    }
    *p++ = '\n';
    return (uint8_t)(p - buf);
}

uint8_t fmt_inputs(char *buf, uint64_t us, uint8_t estop, uint8_t door) {
    char *p = buf;
    *p++ = 'I';
    *p++ = ' ';
    p = fmt_u64(p, us);
    *p++ = ' ';
    *p++ = estop ? '1' : '0';
    *p++ = ' ';
    *p++ = door ? '1' : '0';
    *p++ = '\n';
    return (uint8_t)(p - buf);
}
