/* spinner_host: runs a C/C++ controller (a shared library with `main`) as a child of the
 * simulator and carries its Spinner calls over two pipes (simrunner/run/native/bridge.py).
 *
 *   spinner_host CONTROLLER.so REQUEST_FD REPLY_FD PROGRAM_NAME [ARGS...]
 *
 * The host exports the Spinner API (spinner.h) and usleep/sleep/nanosleep/clock_nanosleep
 * (-rdynamic), so the controller's references bind to them: sleeping waits in simulated
 * time. Requests: {u32 op, u32 length, payload}; replies: {u32 status, u32 length,
 * payload}. Commands and debug data are buffered and sent with the next waiting call (one
 * round trip per camera frame: a write and a readv). A fault (SIGSEGV, SIGBUS, SIGILL,
 * SIGFPE, SIGABRT; stack overflow through an alternate signal stack), a misused call, or
 * SIGUSR1 (the simulator's watchdog asking where a stalled loop is) sends a FAULT report
 * with the raw backtrace (module, offset, symbol per frame); the simulator symbolises it
 * with the debug info.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <execinfo.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <sys/uio.h>
#include <ucontext.h>
#include <unistd.h>

#include "spinner.h"

enum { OP_CMD = 1, OP_TEXT, OP_LINE, OP_IMAGE, OP_SPEED, OP_POSITION, OP_TIME, OP_SLEEP,
       OP_NOISE, OP_PARAM, OP_FAULT };
enum { ST_OK = 0, ST_FINISHED = 1, ST_ERROR = 2 };

static int req_fd = -1, rep_fd = -1;
static unsigned char out_buf[1 << 16];
static size_t out_len;
static int img_h = 128, img_w = 128, line_row = 60, recording_on;
static double wheelbase_m = 0.175;
static int finished;  /* the run is over: calls return at once (atexit, destructors) */
static double last_speed, last_angle, speed_mps, steer_rad;
static spinner_norm_fn f_speed_norm, f_speed_denorm, f_turn_norm, f_diff_norm;
static double last_time_s, last_speed_val, last_pos[3];

static int inited;  /* the run's INIT message read (lazily: the child starts before the run) */

static void fault_report(int sig, const char *message, void *pc);
static void read_init(void);
#define INIT() do { if (!inited) read_init(); } while (0)

/* -- pipe I/O ------------------------------------------------------------------------- */
static void write_all(const void *data, size_t n) {
    const unsigned char *p = data;
    while (n > 0) {
        ssize_t k = write(req_fd, p, n);
        if (k < 0) {
            if (errno == EINTR) continue;
            _exit(75);  /* the simulator is gone */
        }
        p += k;
        n -= (size_t)k;
    }
}

static void read_all(void *data, size_t n) {
    unsigned char *p = data;
    while (n > 0) {
        ssize_t k = read(rep_fd, p, n);
        if (k <= 0) {
            if (k < 0 && errno == EINTR) continue;
            _exit(75);
        }
        p += k;
        n -= (size_t)k;
    }
}

static void flush_out(void) {
    if (out_len) {
        write_all(out_buf, out_len);
        out_len = 0;
    }
}

/* Queue one message (sent with the next waiting call). */
static void queue(uint32_t op, const void *a, size_t na, const void *b, size_t nb) {
    uint32_t hdr[2] = {op, (uint32_t)(na + nb)};
    size_t total = sizeof hdr + na + nb;
    if (out_len + total > sizeof out_buf) flush_out();
    if (total > sizeof out_buf) {
        write_all(hdr, sizeof hdr);
        if (na) write_all(a, na);
        if (nb) write_all(b, nb);
        return;
    }
    memcpy(out_buf + out_len, hdr, sizeof hdr);
    out_len += sizeof hdr;
    if (na) memcpy(out_buf + out_len, a, na), out_len += na;
    if (nb) memcpy(out_buf + out_len, b, nb), out_len += nb;
}

static void skip_in(size_t n) {  /* drop n bytes of a reply (longer than the caller's buffer) */
    unsigned char sink[4096];
    while (n > 0) {
        size_t k = n < sizeof sink ? n : sizeof sink;
        read_all(sink, k);
        n -= k;
    }
}

/* Read a reply's header and as much of its payload as fits `reply` (`size` bytes) with one
 * readv (the simulator writes a reply at once: usually all of it is there); returns the
 * payload bytes read. */
static size_t read_reply_head(uint32_t hdr[2], void *reply, size_t size) {
    struct iovec iov[2] = {{hdr, 2 * sizeof hdr[0]}, {reply, size}};
    ssize_t k;
    do k = readv(rep_fd, iov, size ? 2 : 1); while (k < 0 && errno == EINTR);
    if (k <= 0) _exit(75);  /* the simulator is gone */
    if ((size_t)k < iov[0].iov_len) {
        read_all((unsigned char *)hdr + k, iov[0].iov_len - (size_t)k);
        return 0;
    }
    return (size_t)k - iov[0].iov_len;
}

/* Send a waiting request and read the reply into `reply` (at most `size` bytes); returns the
 * reply's length. The run being over ends the program. */
static size_t call(uint32_t op, const void *a, size_t na, const void *b, size_t nb,
                   void *reply, size_t size) {
    queue(op, a, na, b, nb);
    flush_out();
    uint32_t hdr[2];
    size_t have = read_reply_head(hdr, reply, size);  /* have <= size */
    if (hdr[0] == ST_FINISHED) {
        finished = 1;
        exit(0);
    }
    if (hdr[0] == ST_ERROR) {
        static char msg[1024];
        size_t n = hdr[1] < sizeof msg - 1 ? hdr[1] : sizeof msg - 1;
        size_t c = have < n ? have : n;
        if (c) memcpy(msg, reply, c);
        if (n > c) read_all(msg + c, n - c);
        msg[n] = 0;
        size_t used = have > n ? have : n;  /* more than hdr[1] if a second reply followed */
        if (used < hdr[1]) skip_in(hdr[1] - used);
        fault_report(0, msg, NULL);
    }
    size_t n = hdr[1] < size ? hdr[1] : size;  /* one reply per request: have <= hdr[1] */
    if (n > have) read_all((unsigned char *)reply + have, n - have);
    skip_in(hdr[1] - n);
    return hdr[1];
}

/* -- misuse ---------------------------------------------------------------------------- */
static void misuse(const char *fmt, ...) {
    static char msg[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    fault_report(0, msg, NULL);
}

static double finite_arg(const char *fn, const char *name, double v) {
    if (!isfinite(v)) misuse("%s(%s=%g): expected a finite number", fn, name, v);
    return v;
}

/* -- the API ----------------------------------------------------------------------------- */
void spinner_configure(spinner_norm_fn speed_norm, spinner_norm_fn speed_denorm,
                       spinner_norm_fn turn_norm, spinner_norm_fn diff_norm) {
    if (speed_norm) f_speed_norm = speed_norm;
    if (speed_denorm) f_speed_denorm = speed_denorm;
    if (turn_norm) f_turn_norm = turn_norm;
    if (diff_norm) f_diff_norm = diff_norm;
}

static void send_command(const char *fn, double speed, double angle, int set_speed, int set_steer) {
    if (finished) return;
    if (set_steer) {
        steer_rad = f_turn_norm ? f_turn_norm(speed, angle) : angle;
        if (!isfinite(steer_rad))
            misuse("%s(speed=%g, angle=%g): turn_norm returned %g, expected a finite number",
                   fn, speed, angle, steer_rad);
    }
    if (set_speed) {
        speed_mps = f_speed_norm ? f_speed_norm(speed, angle) : speed;
        if (!isfinite(speed_mps))
            misuse("%s(speed=%g, angle=%g): speed_norm returned %g, expected a finite number",
                   fn, speed, angle, speed_mps);
    }
    double yaw = f_diff_norm ? f_diff_norm(speed_mps, steer_rad)
                             : speed_mps * sin(steer_rad) / wheelbase_m;
    if (!isfinite(yaw))
        misuse("%s(speed=%g, angle=%g): diff_norm returned %g, expected a finite number",
               fn, speed, angle, yaw);
    double cmd[3] = {speed_mps, steer_rad, yaw};
    queue(OP_CMD, cmd, sizeof cmd, NULL, 0);
}

void spinner_set_servo_at(double angle, double speed) {
    INIT();
    last_angle = finite_arg("spinner_set_servo", "angle", angle);
    send_command("spinner_set_servo", finite_arg("spinner_set_servo", "speed", speed), angle, 0, 1);
}

void spinner_set_servo(double angle) { spinner_set_servo_at(angle, last_speed); }

void spinner_set_speed_at(double speed, double angle) {
    INIT();
    last_speed = finite_arg("spinner_set_speed", "speed", speed);
    send_command("spinner_set_speed", speed, finite_arg("spinner_set_speed", "angle", angle), 1, 0);
}

void spinner_set_speed(double speed) { spinner_set_speed_at(speed, last_angle); }

void spinner_set_speed_and_servo(double speed, double angle) {
    INIT();
    last_speed = finite_arg("spinner_set_speed_and_servo", "speed", speed);
    last_angle = finite_arg("spinner_set_speed_and_servo", "angle", angle);
    send_command("spinner_set_speed_and_servo", speed, angle, 1, 1);
}

int spinner_image_width(void) { INIT(); return img_w; }
int spinner_image_height(void) { INIT(); return img_h; }
int spinner_line_row(void) { INIT(); return line_row; }
int spinner_recording(void) { INIT(); return recording_on; }

size_t spinner_get_image(int line, int add_noise, uint8_t *buf, size_t size) {
    INIT();
    if (line < -1 || line >= img_h)
        misuse("spinner_get_image(line=%d): expected -1 (whole image) or a row 0..%d", line, img_h - 1);
    size_t need = line < 0 ? (size_t)img_h * img_w : (size_t)img_w;
    if (buf == NULL || size < need)
        misuse("spinner_get_image(line=%d, size=%zu): the buffer must hold %zu bytes", line, size, need);
    if (finished) return 0;
    int32_t args[2] = {line, add_noise ? 1 : 0};
    return call(OP_IMAGE, args, sizeof args, NULL, 0, buf, size);
}

double spinner_get_speed(void) {
    INIT();
    if (finished) return last_speed_val;
    double v;
    call(OP_SPEED, NULL, 0, NULL, 0, &v, sizeof v);
    last_speed_val = f_speed_denorm ? f_speed_denorm(v, last_angle) : v;
    return last_speed_val;
}

void spinner_get_position(double *x_m, double *y_m, double *z_m) {
    INIT();
    if (!finished) call(OP_POSITION, NULL, 0, NULL, 0, last_pos, sizeof last_pos);
    if (x_m) *x_m = last_pos[0];
    if (y_m) *y_m = last_pos[1];
    if (z_m) *z_m = last_pos[2];
}

double spinner_get_time(void) {
    INIT();
    if (!finished) call(OP_TIME, NULL, 0, NULL, 0, &last_time_s, sizeof last_time_s);
    return last_time_s;
}

void spinner_sleep(double seconds) {
    INIT();
    if (!(seconds >= 0) || !isfinite(seconds))
        misuse("spinner_sleep(seconds=%g): expected a finite number >= 0", seconds);
    if (finished) return;
    call(OP_SLEEP, &seconds, sizeof seconds, NULL, 0, NULL, 0);
}

void spinner_add_text(const char *const *lines, int n) {
    INIT();
    if (finished) return;
    char *buf = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&buf, &len);
    for (int i = 0; i < n; i++) {
        fputs(lines[i] ? lines[i] : "", f);
        fputc(0, f);
    }
    fclose(f);
    int32_t count = n;
    queue(OP_TEXT, &count, sizeof count, buf, len);
    free(buf);
}

void spinner_add_textf(const char *format, ...) {
    char line[1024];
    va_list ap;
    va_start(ap, format);
    vsnprintf(line, sizeof line, format, ap);
    va_end(ap);
    const char *lines[1] = {line};
    spinner_add_text(lines, 1);
}

void spinner_add_line(const uint8_t *pixels, int rows, int width) {
    INIT();
    if (rows < 1 || width < 1 || pixels == NULL)
        misuse("spinner_add_line(rows=%d, width=%d): expected an image line (rows >= 1, width >= 1)",
               rows, width);
    if (finished) return;
    int32_t dims[2] = {rows, width};
    queue(OP_LINE, dims, sizeof dims, pixels, (size_t)rows * width);
}

void spinner_add_noise(uint8_t *pixels, int rows, int width) {
    INIT();
    if (rows < 1 || width < 1 || pixels == NULL)
        misuse("spinner_add_noise(rows=%d, width=%d): expected an image (rows >= 1, width >= 1)",
               rows, width);
    if (finished) return;
    int32_t dims[2] = {rows, width};
    size_t n = (size_t)rows * width;
    call(OP_NOISE, dims, sizeof dims, pixels, n, pixels, n);
}

double spinner_param(const char *name, double default_value) {
    INIT();
    if (name == NULL) misuse("spinner_param(name=NULL): expected a parameter name");
    if (finished) return default_value;
    double v;
    call(OP_PARAM, &default_value, sizeof default_value, name, strlen(name), &v, sizeof v);
    return v;
}

/* -- sleeping in simulated time ------------------------------------------------------------ */
int usleep(useconds_t usec) {
    spinner_sleep(usec * 1e-6);
    return 0;
}

unsigned int sleep(unsigned int seconds) {
    spinner_sleep((double)seconds);
    return 0;
}

int nanosleep(const struct timespec *req, struct timespec *rem) {
    if (req == NULL || req->tv_nsec < 0 || req->tv_nsec >= 1000000000L || req->tv_sec < 0) {
        errno = EINVAL;
        return -1;
    }
    spinner_sleep((double)req->tv_sec + req->tv_nsec * 1e-9);
    if (rem) rem->tv_sec = 0, rem->tv_nsec = 0;
    return 0;
}

int clock_nanosleep(clockid_t clock, int flags, const struct timespec *req, struct timespec *rem) {
    (void)clock;
    if (req == NULL || req->tv_nsec < 0 || req->tv_nsec >= 1000000000L) return EINVAL;
    double s = (double)req->tv_sec + req->tv_nsec * 1e-9;
    if (flags & TIMER_ABSTIME) s -= spinner_get_time();  /* absolute: on the simulated clock */
    spinner_sleep(s > 0 ? s : 0);
    if (rem) rem->tv_sec = 0, rem->tv_nsec = 0;
    return 0;
}

/* -- faults ---------------------------------------------------------------------------- */
static char report[1 << 15];
static size_t report_len;

static void rput(const char *s) {
    size_t n = strlen(s);
    if (report_len + n >= sizeof report) n = sizeof report - 1 - report_len;
    memcpy(report + report_len, s, n);
    report_len += n;
}

static void rhex(uintptr_t v) {
    char tmp[20];
    int i = 0;
    do {
        tmp[i++] = "0123456789abcdef"[v & 15];
        v >>= 4;
    } while (v);
    char out[22] = "0x";
    for (int k = 0; k < i; k++) out[2 + k] = tmp[i - 1 - k];
    out[2 + i] = 0;
    rput(out);
}

static void rdec(long v) {
    char tmp[24];
    int i = 0, neg = v < 0;
    unsigned long u = neg ? -(unsigned long)v : (unsigned long)v;
    do {
        tmp[i++] = (char)('0' + u % 10);
        u /= 10;
    } while (u);
    char out[26];
    int k = 0;
    if (neg) out[k++] = '-';
    while (i) out[k++] = tmp[--i];
    out[k] = 0;
    rput(out);
}

/* Text report: "signal N\nmessage TEXT\npc ADDR\nframe ADDR OFFSET PATH\tSYMBOL\n"... */
static void fault_report(int sig, const char *message, void *pc) {
    void *frames[128];
    int n = backtrace(frames, 128);
    report_len = 0;
    rput("signal ");
    rdec(sig);
    rput("\nmessage ");
    rput(message ? message : "");
    rput("\n");
    if (pc) {
        rput("pc ");
        rhex((uintptr_t)pc);
        rput("\n");
    }
    for (int i = 0; i < n; i++) {
        Dl_info info;
        rput("frame ");
        rhex((uintptr_t)frames[i]);
        if (dladdr(frames[i], &info) && info.dli_fname) {
            rput(" ");
            rhex((uintptr_t)frames[i] - (uintptr_t)info.dli_fbase);
            rput(" ");
            rput(info.dli_fname);
            rput("\t");
            rput(info.dli_sname ? info.dli_sname : "");
        } else {
            rput(" 0x0 ?\t");
        }
        rput("\n");
    }
    flush_out();
    uint32_t hdr[2] = {OP_FAULT, (uint32_t)report_len};
    write_all(hdr, sizeof hdr);
    write_all(report, report_len);
    if (sig > 0 && sig != SIGUSR1) {
        signal(sig, SIG_DFL);
        raise(sig);
    }
    _exit(sig == SIGUSR1 ? 76 : 70);
}

static void on_fault(int sig, siginfo_t *info, void *context) {
    void *pc = NULL;
    uintptr_t sp = 0;
    ucontext_t *uc = context;
#if defined(__x86_64__)
    pc = (void *)uc->uc_mcontext.gregs[REG_RIP];
    sp = (uintptr_t)uc->uc_mcontext.gregs[REG_RSP];
#elif defined(__aarch64__)
    pc = (void *)uc->uc_mcontext.pc;
    sp = (uintptr_t)uc->uc_mcontext.sp;
#else
    (void)uc;
#endif
    uintptr_t addr = (uintptr_t)info->si_addr;
    int overflow = sig == SIGSEGV && sp && addr + 65536 > sp && addr < sp + 65536;
    fault_report(sig, overflow ? "stack overflow (the stack limit is `ulimit -s`)" : "", pc);
}

static void install_handlers(void) {
    static char alt_stack[1 << 16];
    stack_t ss = {.ss_sp = alt_stack, .ss_size = sizeof alt_stack, .ss_flags = 0};
    sigaltstack(&ss, NULL);
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_sigaction = on_fault;
    sa.sa_flags = SA_SIGINFO | SA_ONSTACK;
    sigemptyset(&sa.sa_mask);
    int sigs[] = {SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT, SIGUSR1};
    for (size_t i = 0; i < sizeof sigs / sizeof sigs[0]; i++) sigaction(sigs[i], &sa, NULL);
    void *warm[2];
    backtrace(warm, 2);  /* loads the unwinder now, not inside a signal handler */
}

static void read_init(void) {
    double init[5];  /* height, width, line row, recording, wheelbase */
    inited = 1;
    read_all(init, sizeof init);
    img_h = (int)init[0], img_w = (int)init[1], line_row = (int)init[2];
    recording_on = (int)init[3], wheelbase_m = init[4];
}

/* -- start ------------------------------------------------------------------------------ */
int main(int argc, char **argv) {
    if (argc < 5) {
        fprintf(stderr, "usage: spinner_host CONTROLLER.so REQUEST_FD REPLY_FD NAME [ARGS...]\n");
        return 64;
    }
    req_fd = atoi(argv[2]);
    rep_fd = atoi(argv[3]);
    setvbuf(stdout, NULL, _IOLBF, 0);  /* the controller's prints reach the terminal in order */
    install_handlers();
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_GLOBAL);
    if (lib == NULL) {
        fprintf(stderr, "simrunner: %s\n", dlerror());
        return 71;
    }
    int (*user_main)(int, char **, char **) = (int (*)(int, char **, char **))dlsym(lib, "main");
    if (user_main == NULL) return 72;  /* the simulator says so, naming the sources */
    extern char **environ;
    INIT();  /* the run has started */
    int rc = user_main(argc - 4, argv + 4, environ);
    flush_out();
    exit(rc);
}
