/* Host test of the firmware's line lexer and formatting (firmware/trigger-box/proto.c). */
#include <stdio.h>
#include <string.h>

#include "proto.h"

static int failures;

static command_t run(const char *line) {
    lexer_t lx;
    lx_reset(&lx);
    command_t c = {.kind = 255};
    for (const char *p = line; *p; p++) {
        uint8_t ready = *p == '\n' && lx_fire_ready(&lx);
        if (lx_push(&lx, (uint8_t)*p)) {
            lx_finish(&lx, &c);
            /* The firmware's fast path must agree with the full parse. */
            if (ready != (c.kind == CMD_FIRE && c.err == 0)) {
                printf("FAIL fast path disagrees on %s", line);
                failures++;
            }
        }
    }
    return c;
}

static void expect(const char *line, uint8_t kind, uint8_t err, uint32_t seq, uint32_t a,
                   uint32_t b) {
    command_t c = run(line);
    if (c.kind != kind || c.err != err || c.seq != seq || c.a != a || c.b != b) {
        printf("FAIL %-40.40s -> kind %u err %u seq %lu a %lu b %lu (want %u %u %lu %lu %lu)\n",
               line, c.kind, c.err, (unsigned long)c.seq, (unsigned long)c.a,
               (unsigned long)c.b, kind, err, (unsigned long)seq, (unsigned long)a,
               (unsigned long)b);
        failures++;
    }
}

static void expect_text(const char *got, size_t n, const char *want) {
    if (n != strlen(want) || memcmp(got, want, n) != 0) {
        printf("FAIL format: got '%.*s' want '%s'\n", (int)n, got, want);
        failures++;
    }
}

int main(void) {
    expect("P 1\n", CMD_PING, 0, 1, 0, 0);
    expect("V 7\n", CMD_VERSION, 0, 7, 0, 0);
    expect("P 1\r\n", CMD_PING, 0, 1, 0, 0);
    expect("F 3 1500 3\n", CMD_FIRE, 0, 3, 3, 0);
    expect("F 4294967295 18446744073709551615 1\n", CMD_FIRE, 0, 4294967295u, 1, 0);
    expect("F 5 000000000000018446744073709551615 1\n", CMD_FIRE, 0, 5, 1, 0);
    expect("F 5 18446744073709551616 1\n", CMD_FIRE, ERR_SYNTAX, 5, 0, 0);
    expect("F 5 99999999999999999999 1\n", CMD_FIRE, ERR_SYNTAX, 5, 0, 0);
    expect("F 5 184467440737095516150 1\n", CMD_FIRE, ERR_SYNTAX, 5, 0, 0);
    expect("F 5 0 1\n", CMD_FIRE, 0, 5, 1, 0);
    expect("F 6 1 0\n", CMD_FIRE, ERR_SYNTAX, 6, 0, 0);
    expect("F 6 1 4\n", CMD_FIRE, ERR_SYNTAX, 6, 4, 0);
    expect("F 6 1\n", CMD_FIRE, ERR_SYNTAX, 6, 0, 0);
    expect("F 6 1 1 1\n", CMD_FIRE, ERR_SYNTAX, 6, 0, 0);
    expect("L 2 650\n", CMD_LEVEL, 0, 2, 650, 0);
    expect("L 2 1000\n", CMD_LEVEL, 0, 2, 1000, 0);
    expect("L 2 1001\n", CMD_LEVEL, ERR_SYNTAX, 2, 1001, 0);
    expect("S 9 1000 2000\n", CMD_STROBE, 0, 9, 1000, 2000);
    expect("S 9 1000 4294967295\n", CMD_STROBE, 0, 9, 1000, 4294967295u);
    expect("S 9 1000 4294967296\n", CMD_STROBE, ERR_SYNTAX, 9, 0, 0);
    expect("S 9 1000 0\n", CMD_STROBE, ERR_SYNTAX, 9, 1000, 0);
    expect("P 0\n", CMD_PING, ERR_SYNTAX, 0, 0, 0);
    expect("P 4294967296\n", CMD_PING, ERR_SYNTAX, 0, 0, 0);
    expect("P -1\n", CMD_PING, ERR_SYNTAX, 0, 0, 0);
    expect("P +1\n", CMD_PING, ERR_SYNTAX, 0, 0, 0);
    expect("P  1\n", CMD_PING, ERR_SYNTAX, 1, 0, 0);
    expect("P 1 \n", CMD_PING, ERR_SYNTAX, 1, 0, 0);
    expect(" P 1\n", CMD_PING, ERR_SYNTAX, 1, 0, 0);
    expect("P\n", CMD_PING, ERR_SYNTAX, 0, 0, 0);
    expect("P 1\rx\n", CMD_PING, ERR_SYNTAX, 0, 0, 0);
    expect("X 9\n", CMD_UNKNOWN, ERR_UNKNOWN, 9, 0, 0);
    expect("PING 9\n", CMD_UNKNOWN, ERR_UNKNOWN, 9, 0, 0);
    expect("p 9\n", CMD_UNKNOWN, ERR_UNKNOWN, 9, 0, 0);
    expect("\n", CMD_NONE, 0, 0, 0, 0);
    expect("\r\n", CMD_NONE, 0, 0, 0, 0);
    /* 63 bytes and '\n' is the longest line; 64 and '\n' is too long. */
    char line[80];
    memset(line, '0', sizeof line);
    memcpy(line, "P 1 ", 4);
    line[63] = '\n';
    line[64] = 0;
    expect(line, CMD_PING, ERR_SYNTAX, 1, 0, 0); /* fits, but has an extra field */
    memcpy(line, "P ", 2);
    line[2] = '1';
    line[3] = '0'; /* "P 1000...0" (61 digits): seq overflows */
    expect(line, CMD_PING, ERR_SYNTAX, 0, 0, 0);
    memset(line, '0', sizeof line);
    memcpy(line, "P 1 ", 4);
    line[64] = '\n';
    line[65] = 0;
    expect(line, CMD_UNKNOWN, ERR_SYNTAX, 0, 0, 0);
    /* After a too-long line the next one is read normally. */
    {
        lexer_t lx;
        lx_reset(&lx);
        command_t c;
        for (int i = 0; i < 100; i++)
            lx_push(&lx, 'x');
        if (lx_push(&lx, '\n'))
            lx_finish(&lx, &c);
        const char *next = "P 2\n";
        for (const char *p = next; *p; p++)
            if (lx_push(&lx, (uint8_t)*p))
                lx_finish(&lx, &c);
        if (c.kind != CMD_PING || c.err || c.seq != 2) {
            printf("FAIL line after a too-long one\n");
            failures++;
        }
    }

    char buf[PROTO_MAX_LINE];
    uint8_t n = fmt_answer(buf, 'A', 3, 0, 1251002, "2", "0.1.0");
    expect_text(buf, n, "A 3 1251002\n");
    n = fmt_answer(buf, 'E', 0, 3, 0, "2", "0.1.0");
    expect_text(buf, n, "E 0 3\n");
    n = fmt_answer(buf, 'V', 4294967295u, 0, 18446744073709551615ull, "2", "0.1.0");
    expect_text(buf, n, "V 4294967295 18446744073709551615 2 0.1.0\n");
    n = fmt_inputs(buf, 4294967296ull, 1, 0);
    expect_text(buf, n, "I 4294967296 1 0\n");
    n = fmt_inputs(buf, 5000000000ull, 0, 1);
    expect_text(buf, n, "I 5000000000 0 1\n");
    n = fmt_inputs(buf, 1000000000000ull, 0, 0);
    expect_text(buf, n, "I 1000000000000 0 0\n");
    n = fmt_inputs(buf, 0, 0, 0);
    expect_text(buf, n, "I 0 0 0\n");

    if (failures) {
        printf("proto-test: %d failures\n", failures);
        return 1;
    }
    printf("proto-test: lexer and formatting ok\n");
    return 0;
}
