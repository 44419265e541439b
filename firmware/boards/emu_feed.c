/* The file feed of the emulated boards: see emu_feed.h. */
#include "emu_feed.h"

#include "acn_board.h"
#include "semihost.h"

#define MODE_RB 1u /* fopen "rb" */
#define MODE_WB 5u /* fopen "wb" */
#define MARKER "accelnav-feed "

#define IN_SIZE 512u
#define OUT_SIZE 512u

static int fd_in = -1;
static int fd_out = -1;
static uint8_t in_buf[IN_SIZE];
static uint32_t in_len, in_pos;
static uint8_t out_buf[OUT_SIZE];

static void feed_exit(int status, const char *why)
{
    uint32_t arg;
    if (why) {
        semihost_call(SEMIHOST_SYS_WRITE0, why);
    }
    arg = status == 0 ? SEMIHOST_EXIT_OK : SEMIHOST_EXIT_ERROR;
    semihost_call(SEMIHOST_SYS_EXIT, (const void *)arg);
    for (;;) {
    }
}

static int open_file(const char *name, uint32_t len, uint32_t mode)
{
    uint32_t args[3];
    args[0] = (uint32_t)name;
    args[1] = mode;
    args[2] = len;
    return semihost_call(SEMIHOST_SYS_OPEN, args);
}

/* The word of s starting at or after *pos (spaces skipped), NUL-terminated in place; *pos moves
 * past it. NULL when there is none. */
static const char *next_word(char *s, uint32_t *pos)
{
    uint32_t i = *pos, start;
    while (s[i] == ' ') {
        ++i;
    }
    start = i;
    while (s[i] != '\0' && s[i] != ' ') {
        ++i;
    }
    if (i == start) {
        return 0;
    }
    *pos = s[i] == '\0' ? i : i + 1u;
    s[i] = '\0';
    return &s[start];
}

static uint32_t str_len(const char *s)
{
    uint32_t n = 0;
    while (s[n] != '\0') {
        ++n;
    }
    return n;
}

bool emu_feed_start(void)
{
    char *cmd = (char *)in_buf; /* the command line is read once, before any stimulus */
    uint32_t args[2];
    uint32_t i, pos = sizeof MARKER - 1u;
    const char *in, *out;
    args[0] = (uint32_t)cmd;
    args[1] = IN_SIZE - 1u;
    if (semihost_call(SEMIHOST_SYS_GET_CMDLINE, args) != 0) {
        return false;
    }
    for (i = 0; i < sizeof MARKER - 1u; ++i) {
        if (cmd[i] != MARKER[i]) {
            return false; /* no feed named: the UARTs */
        }
    }
    in = next_word(cmd, &pos);
    out = next_word(cmd, &pos);
    if (!in || !out) {
        feed_exit(1, "accelnav-feed: expected the stimulus and telemetry file names\n");
    }
    fd_in = open_file(in, str_len(in), MODE_RB);
    fd_out = open_file(out, str_len(out), MODE_WB);
    if (fd_in < 0 || fd_out < 0) {
        feed_exit(1, "accelnav-feed: cannot open the stimulus or the telemetry file\n");
    }
    in_len = in_pos = 0;
    return true;
}

/* Write the whole telemetry queue to OUT. */
static void flush_out(void)
{
    uint32_t args[3];
    uint32_t n;
    uint8_t b;
    do {
        for (n = 0; n < OUT_SIZE && emu_txq_next(&b); ++n) {
            out_buf[n] = b;
        }
        if (n == 0) {
            return;
        }
        args[0] = (uint32_t)fd_out;
        args[1] = (uint32_t)out_buf;
        args[2] = n;
        if (semihost_call(SEMIHOST_SYS_WRITE, args) != 0) { /* the count of bytes not written */
            feed_exit(1, "accelnav-feed: cannot write the telemetry file\n");
        }
    } while (n == OUT_SIZE);
}

static void feed_end(void)
{
    int fd;
    flush_out();
    fd = fd_in;
    semihost_call(SEMIHOST_SYS_CLOSE, &fd);
    fd = fd_out;
    if (semihost_call(SEMIHOST_SYS_CLOSE, &fd) != 0) {
        feed_exit(1, "accelnav-feed: cannot close the telemetry file\n");
    }
    feed_exit(0, 0);
}

void emu_feed_poll(void)
{
    uint32_t args[3];
    int left;
    if (emu_txq_free() < 3u * ACNF_MAX_UP_WIRE) {
        flush_out();
    }
    while (emu_txq_free() >= 3u * ACNF_MAX_UP_WIRE) {
        if (in_pos == in_len) {
            args[0] = (uint32_t)fd_in;
            args[1] = (uint32_t)in_buf;
            args[2] = IN_SIZE;
            left = semihost_call(SEMIHOST_SYS_READ, args); /* the count of bytes not read */
            if (left < 0 || left > (int)IN_SIZE) {
                feed_exit(1, "accelnav-feed: cannot read the stimulus file\n");
            }
            in_len = IN_SIZE - (uint32_t)left;
            in_pos = 0;
            if (in_len == 0u) {
                feed_end(); /* the end of the stimulus */
            }
        }
        app_rx(APP_CH_HOST, &in_buf[in_pos++], 1);
    }
}
