/* spinner_host: runs a C/C++ controller (a shared library with `main`) and carries its
 * Spinner calls to the simulator (simrunner/run/native/bridge.py). Built two ways:
 *
 * - the host program (default): a child process of the simulator, talking over two pipes,
 *     spinner_host CONTROLLER.so REQUEST_FD REPLY_FD PROGRAM_NAME [ARGS...]
 *   It exports the Spinner API (spinner.h) and usleep/sleep/nanosleep/clock_nanosleep
 *   (-rdynamic), so a prebuilt controller's references bind to them.
 * - the in-process library (-DSPINNER_INPROC, libspinner_inproc.so): loaded into the
 *   simulator, it runs the program's `main` as a coroutine on a stack of its own. A waiting
 *   call switches back to the simulator with the requests; the simulator answers and
 *   switches in again (no process hand-off). Controllers built by simrunner are linked with
 *   --wrap for the sleeps and exits (__wrap_usleep, __wrap_exit, ...), defined in both.
 *
 * Requests: {u32 op, u32 length, payload}; replies: {u32 status, u32 length, payload}.
 * Commands and debug data are buffered and handed over with the next waiting call (one
 * round trip per camera frame). A fault (SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT; stack
 * overflow through an alternate signal stack), a misused call, or the simulator's watchdog
 * asking where a stalled loop is (SIGUSR1; in-process also the reply ST_WHERE) sends a FAULT
 * report with the raw backtrace (module, offset, symbol per frame); the simulator symbolises
 * it with the debug info. A call from a thread of the program's own is reported by main()'s
 * thread with that thread's backtrace, and main()'s own as "noticed" lines (foreign_noted). A
 * fault in such a thread is reported from it, naming it as one (thread_fault), and the process
 * dies by the signal. In-process, a fault ends the coroutine (the simulator goes on);
 * a signal that is not the controller's goes to the handler installed before. A fault in the
 * program's constructors as its library is loaded (spinner_inproc_open, before any run: nothing
 * can return out of the loader) writes the same report to the file descriptor the simulator
 * handed in (its supervisor's report file) and the process dies by the signal; an exit,
 * spinner_fail or a misused call there writes its report there too and the process ends with
 * status 70 (load_ended). So does a fault in a thread of the program's during its run (to the
 * descriptor handed in for the run, spinner_inproc_start): nothing can leave main()'s coroutine
 * from that thread.
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
#include <sched.h>
#include <time.h>
#include <sys/uio.h>
#include <ucontext.h>
#include <unistd.h>
#include <pthread.h>
#include <sys/prctl.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <link.h>
#include <sys/mman.h>
#include <sys/syscall.h>
#ifdef SPINNER_INPROC
#include <sys/resource.h>
#endif

#include "spinner.h"
#include "pixy2_line.h"

enum { OP_CMD = 1, OP_TEXT, OP_LINE, OP_IMAGE, OP_SPEED, OP_POSITION, OP_TIME, OP_SLEEP,
       OP_NOISE, OP_PARAM, OP_FAULT, OP_SET_EXPOSURE, OP_GET_EXPOSURE, OP_PIXY_FEATURES,
       OP_PIXY_SET, OP_PIXY_PROG, OP_DISTANCE, OP_SCAN, OP_ENCODER, OP_IMU, OP_CPU, OP_MOTORS,
       OP_EVERY, OP_ISR_DONE, OP_EVERY_STOP, OP_WARN, OP_LATEST_IMAGE, OP_NOW, OP_IRQ_MASK,
       OP_IRQ_MASK_WAIT, OP_EVERY_UNPEND, OP_PEND, OP_PEND_WAIT, OP_EVERY_PENDING, OP_EXIT_AT,
       OP_FREE_RUNNING, OP_SET_EXPOSURE_NEXT, OP_EVERY_STOP_LATCHED, OP_NOW_UNCHARGED };
enum { ST_OK = 0, ST_FINISHED = 1, ST_ERROR = 2, ST_WHERE = 3, ST_ISR = 4 };

static unsigned char out_buf[1 << 16];
static size_t out_len;
static int img_h = 128, img_w = 128, line_row = 60, recording_on;
static double wheelbase_m = 0.175;
static int encoder_mask, encoder_lines, encoder_per_line, has_imu;  /* the car's [encoders], [imu] */
static int finished;  /* the run is over: calls return at once (atexit, destructors) */
static int run_over;  /* the simulator ended the run (ST_FINISHED): an exit then is not the program's */
static double last_speed, last_angle, speed_mps, steer_rad;
static spinner_norm_fn f_speed_norm, f_speed_denorm, f_turn_norm, f_diff_norm;
static double last_time_s, last_speed_val, last_pos[3];

static int inited;  /* the run's INIT message read (lazily: the child starts before the run) */
#ifdef SPINNER_INPROC
/* In the simulator's process the program's library is loaded (spinner_inproc_open) before its
 * run, and its constructors run then: a call of a global object's constructor (a C++ driver class
 * built on the kit's objects, a Spinner call) has no run to ask. It is not taken for the run's
 * start (which left the run's INIT message unread: the run crashed, SIGSEGV before its first
 * frame); its replies are zeros, and spinner_inproc_early tells the simulator, which runs such a
 * program in a child process (--isolate), where its constructors run with the run there (on the
 * board they run in the start-up code, before main). A run of it here ends at its start saying
 * why (entry). */
static __thread int opening;     /* this thread is loading a program's library (its constructors run) */
static __thread int early_calls; /* calls during the open under way (this thread's) */
#define MAX_EARLY 64
static void *early_libs[MAX_EARLY];  /* the libraries whose loading made them (early_lock) */
static pthread_mutex_t early_lock = PTHREAD_MUTEX_INITIALIZER;
static void load_ended(const char *call, int status, const char *message) __attribute__((noreturn));
#define OPENING() opening
#else
#define OPENING() 0
static int loading;  /* main() is opening the program's library: its constructors run (exit_note) */
#endif

static void fault_report(int sig, const char *message, void *pc);
static void ended(void) __attribute__((noreturn));
static void read_init(void);
#define INIT() do { \
        if (OPENING()) early_calls_seen(); \
        else { if (!inited) read_init(); foreign_check(); } \
    } while (0)
#ifdef SPINNER_INPROC
/* A call of a constructor as its library is loaded here (spinner_inproc_open): seen, and answered
 * at once as after a run's end (foreign_thread: requests dropped, replies zeros; spinner_param its
 * default) - never taken for the run's start, nor for a call of another thread's run under way. */
static void early_calls_seen(void) { early_calls = 1; }
#else
static void early_calls_seen(void) {}
#endif

/* Spinner calls from a thread other than the one running main(): they cannot reach the
 * simulator (they return 0; a misused one ends its thread, foreign_misuse). That thread cannot be
 * stopped safely, nor report (the simulator talks to main()'s thread): the first such call's
 * thread keeps its backtrace (foreign_noted), and the next call from main()'s thread reports the
 * misuse from those frames (foreign_call_report): the line named is the thread's call, the one
 * to change, with main()'s call that noticed it beside it. */
enum { FOREIGN_NONE, FOREIGN_TAKING, FOREIGN_TAKEN, FOREIGN_REPORTED };  /* foreign_calls */
#define FOREIGN_FRAMES 64
static pthread_t api_thread;
static int foreign_calls;  /* FOREIGN_*: atomic (the frames are the taking thread's until TAKEN) */
static void *foreign_frames[FOREIGN_FRAMES];
static int foreign_depth;
static char foreign_message[512];  /* a misused call's message ("": a call that returned 0) */
static void foreign_call_report(void);
static void forked_call(void) __attribute__((noreturn));
static volatile sig_atomic_t forked;  /* this process is one the controller fork()ed (below) */

/* The first foreign call: this thread's backtrace and, for a misused call, its message (outside
 * a signal handler: backtrace may load the unwinder). Later ones add nothing. */
static void foreign_noted(const char *message) {
    int none = FOREIGN_NONE;
    if (!__atomic_compare_exchange_n(&foreign_calls, &none, FOREIGN_TAKING, 0, __ATOMIC_ACQ_REL,
                                     __ATOMIC_ACQUIRE))
        return;
    foreign_depth = backtrace(foreign_frames, FOREIGN_FRAMES);
    snprintf(foreign_message, sizeof foreign_message, "%s", message ? message : "");
    __atomic_store_n(&foreign_calls, FOREIGN_TAKEN, __ATOMIC_RELEASE);
}

/* This thread is not the one running main() (the run under way's; not a constructor's at the load). */
static int on_foreign_thread(void) {
    return !OPENING() && inited && !pthread_equal(pthread_self(), api_thread);
}

static int foreign_thread(void) {
    if (forked) forked_call();
    if (OPENING()) return 1;  /* a constructor's call at the load (INIT): answered here */
    if (!on_foreign_thread()) return 0;
    if (!finished) foreign_noted(NULL);
    return 1;
}

/* main()'s thread (only: a foreign thread's next call must not report from there) reports a
 * foreign call at its next call. */
static void foreign_check(void) {
    if (__atomic_load_n(&foreign_calls, __ATOMIC_ACQUIRE) == FOREIGN_TAKEN && !on_foreign_thread())
        foreign_call_report();
}

/* --mcu-time measured: each request is preceded by the CPU time this thread spent since the
 * previous request or reply (OP_CPU, one double): the program's own processing time. */
static int mcu_report;
static int mcu_on;  /* --mcu-time measured or fixed: the program's own code lets time pass */
static double mcu_mark_s;
static double thread_cpu_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

#ifdef SPINNER_INPROC
/* -- in-process I/O: requests collect in out_buf; a read with nothing left of the reply
 * switches to the simulator, which takes the requests and switches back with the reply. */
/* Context switches. On x86-64 a few instructions (the callee-saved registers, MXCSR and the
 * x87 control word, then the stack pointer): no system call, unlike swapcontext's signal
 * mask. Elsewhere ucontext. co_start runs entry() on a fresh stack. */
static void entry(void);
#if defined(__x86_64__)
#define FAST_SWITCH 1
void spinner_switch(void **save_sp, void *to_sp);
__asm__(".text\n"
        ".globl spinner_switch\n"
        ".hidden spinner_switch\n"
        ".type spinner_switch,@function\n"
        "spinner_switch:\n"
        "  pushq %rbp\n  pushq %rbx\n  pushq %r12\n  pushq %r13\n  pushq %r14\n  pushq %r15\n"
        "  subq $8, %rsp\n  stmxcsr (%rsp)\n  fnstcw 4(%rsp)\n"
        "  movq %rsp, (%rdi)\n  movq %rsi, %rsp\n"
        "  ldmxcsr (%rsp)\n  fldcw 4(%rsp)\n  addq $8, %rsp\n"
        "  popq %r15\n  popq %r14\n  popq %r13\n  popq %r12\n  popq %rbx\n  popq %rbp\n"
        "  ret\n"
        ".size spinner_switch, .-spinner_switch\n");
static void *sim_sp, *co_sp;
static void co_start(void) { entry(); }
static void ctx_make(void *stack_lo_p, size_t size) {
    uintptr_t top = ((uintptr_t)stack_lo_p + size) & ~(uintptr_t)15;
    uint64_t *f = (uint64_t *)(top - 72);  /* what spinner_switch pops, then co_start's return */
    uint32_t mxcsr;
    uint16_t cw;
    __asm__ volatile("stmxcsr %0\n fnstcw %1" : "=m"(mxcsr), "=m"(cw));
    f[0] = (uint64_t)mxcsr | (uint64_t)cw << 32;  /* as spinner_switch stores them */
    for (int i = 1; i <= 6; i++) f[i] = 0;  /* r15 r14 r13 r12 rbx rbp */
    f[7] = (uint64_t)(uintptr_t)co_start;   /* "returned" to, with rsp = top - 8 */
    f[8] = 0;                               /* co_start's return address: the end */
    co_sp = f;
}
#define TO_SIM() spinner_switch(&co_sp, sim_sp)
#define TO_CO() spinner_switch(&sim_sp, co_sp)
#define ESCAPE() do { void *dead; spinner_switch(&dead, sim_sp); } while (0)
#else
static ucontext_t sim_ctx, co_ctx;
static void ctx_make(void *stack_lo_p, size_t size) {
    getcontext(&co_ctx);
    co_ctx.uc_stack.ss_sp = stack_lo_p;
    co_ctx.uc_stack.ss_size = size;
    co_ctx.uc_link = NULL;
    makecontext(&co_ctx, entry, 0);
}
#define TO_SIM() swapcontext(&co_ctx, &sim_ctx)
#define TO_CO() swapcontext(&sim_ctx, &co_ctx)
#define ESCAPE() setcontext(&sim_ctx)
#endif
static sigset_t run_mask;                    /* the simulator's signal mask (restored on escape) */
static volatile sig_atomic_t in_controller;  /* the controller's code runs (signals are its) */
static volatile sig_atomic_t gone;           /* the controller ended (returned, exited, fault) */
static int exit_code;
static const unsigned char *rep_buf;         /* the reply handed in (valid until switched out) */
static size_t rep_len, rep_pos;
static const unsigned char *rep_more;        /* then these bytes (a camera frame's image) or NULL */
static size_t rep_more_len;
static uint32_t frame_head[2];               /* a camera frame's reply header (resume_image) */
static volatile double resumed_at_s;         /* monotonic time of the last switch in */
static pthread_t sim_thread_id;              /* the thread that runs the simulator */

static void switch_out(void) {
    if (forked) forked_call();  /* the copy of the simulator in a forked child never runs */
    in_controller = 0;
    TO_SIM();
    in_controller = 1;
}

/* Outside the controller's run (an atexit handler or a destructor the unloading runs, a
 * thread it left) there is no simulator to switch to: requests are dropped and replies are
 * zeros (the calls return at once, as after the run's end). */
static void write_all(const void *data, size_t n) {
    const unsigned char *p = data;
    if (!in_controller || !pthread_equal(pthread_self(), sim_thread_id)) return;
    while (n > 0) {
        if (out_len == sizeof out_buf) switch_out();  /* the simulator takes it all */
        size_t k = sizeof out_buf - out_len;
        if (k > n) k = n;
        memcpy(out_buf + out_len, p, k);
        out_len += k;
        p += k;
        n -= k;
    }
}

static void read_all(void *data, size_t n) {
    unsigned char *p = data;
    if (!in_controller || !pthread_equal(pthread_self(), sim_thread_id)) {
        memset(p, 0, n);
        return;
    }
    while (n > 0) {
        if (rep_pos == rep_len) {
            if (rep_more != NULL) {  /* a camera frame's image after its header */
                rep_buf = rep_more, rep_len = rep_more_len, rep_pos = 0;
                rep_more = NULL;
                continue;
            }
            fflush(stdout);  /* the controller's prints reach the terminal in order */
            switch_out();
            continue;
        }
        size_t k = rep_len - rep_pos;
        if (k > n) k = n;
        memcpy(p, rep_buf + rep_pos, k);
        rep_pos += k;
        p += k;
        n -= k;
    }
}

static void flush_out(void) {}  /* handed over at the next switch */

static void queue_raw(uint32_t op, const void *a, size_t na, const void *b, size_t nb) {
    uint32_t hdr[2] = {op, (uint32_t)(na + nb)};
    write_all(hdr, sizeof hdr);
    if (na) write_all(a, na);
    if (nb) write_all(b, nb);
}

static size_t read_reply_head(uint32_t hdr[2], void *reply, size_t size) {
    (void)reply, (void)size;
    read_all(hdr, 2 * sizeof hdr[0]);
    return 0;
}

#else
/* -- pipe I/O (the host program) ------------------------------------------------------ */
static int req_fd = -1, rep_fd = -1;
static pthread_t host_thread;  /* the host's main thread, which runs the program's main() */

/* The requests are main()'s thread's (another thread's calls send nothing: foreign_thread), but a
 * thread of the program's own that faults reports from itself (thread_fault): whole messages go
 * to the pipe under pipe_take (flush_out, a long message, a report), so that report comes between
 * two of main()'s messages, never inside one, and the thread that sends a report keeps the pipe
 * (nothing after the report: the process ends with it). Main()'s thread takes it again in a
 * signal handler that interrupted its own write (the simulator's SIGUSR1 asking where: that
 * report goes where the write was, as before). A spin lock (a thread waits for one message); a
 * report waiting for it goes first (pipe_report: main()'s thread, writing one message after
 * another, took it back each time before the reporting thread could, for seconds). */
static uintptr_t pipe_owner;  /* the thread sending (its pthread_self, no system call), 0 none: atomic */
static int pipe_depth;        /* the owner's takes */
static int pipe_report;       /* a report waits for the pipe: no other message takes it (atomic) */
static void pipe_take(int for_report) {
    uintptr_t self = (uintptr_t)pthread_self(), none = 0;
    if (__atomic_load_n(&pipe_owner, __ATOMIC_ACQUIRE) == self) {
        pipe_depth++;
        return;
    }
    if (for_report) __atomic_store_n(&pipe_report, 1, __ATOMIC_RELEASE);
    while ((!for_report && __atomic_load_n(&pipe_report, __ATOMIC_ACQUIRE)) ||
           !__atomic_compare_exchange_n(&pipe_owner, &none, self, 0, __ATOMIC_ACQ_REL, __ATOMIC_ACQUIRE)) {
        none = 0;
        sched_yield();
    }
    pipe_depth = 1;
}
static void pipe_give(void) {
    if (--pipe_depth == 0) __atomic_store_n(&pipe_owner, 0, __ATOMIC_RELEASE);
}

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
        pipe_take(0);
        write_all(out_buf, out_len);
        pipe_give();
        out_len = 0;
    }
}

/* Queue one message (sent with the next waiting call). */
static void queue_raw(uint32_t op, const void *a, size_t na, const void *b, size_t nb) {
    uint32_t hdr[2] = {op, (uint32_t)(na + nb)};
    size_t total = sizeof hdr + na + nb;
    if (out_len + total > sizeof out_buf) flush_out();
    if (total > sizeof out_buf) {
        pipe_take(0);
        write_all(hdr, sizeof hdr);
        if (na) write_all(a, na);
        if (nb) write_all(b, nb);
        pipe_give();
        return;
    }
    memcpy(out_buf + out_len, hdr, sizeof hdr);
    out_len += sizeof hdr;
    if (na) memcpy(out_buf + out_len, a, na), out_len += na;
    if (nb) memcpy(out_buf + out_len, b, nb), out_len += nb;
}

#endif

static int isr_depth;   /* handlers running (spinner_in_interrupt) */
static int now_known;   /* spinner_now's answer, now_time_s, holds (no time passed since it was asked) */
static double now_time_s;

static void queue(uint32_t op, const void *a, size_t na, const void *b, size_t nb) {
    if (foreign_thread()) return;
    if (mcu_on && isr_depth == 0) now_known = 0;  /* --mcu-time: the call lets the code's time pass */
    if (mcu_report) {
        double now = thread_cpu_s(), spent = now - mcu_mark_s;
        mcu_mark_s = now;
        queue_raw(OP_CPU, &spent, sizeof spent, NULL, 0);
    }
    queue_raw(op, a, na, b, nb);
}

static void skip_in(size_t n) {  /* drop n bytes of a reply (longer than the caller's buffer) */
    unsigned char sink[4096];
    while (n > 0) {
        size_t k = n < sizeof sink ? n : sizeof sink;
        read_all(sink, k);
        n -= k;
    }
}

#ifndef SPINNER_INPROC
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
#endif

/* Timer interrupts (spinner_every, --isr NAME@HZ): the handlers by slot. The simulator runs one
 * by answering a waiting call with ST_ISR {int32 slot, double time}: the call runs the handler (its requests
 * go out as usual; no simulated time passes in it), sends OP_ISR_DONE and waits on for its own
 * reply - the handler runs on the program's stack inside the waiting call, as an interrupt.
 * spinner_stop_every frees a handler's slots (OP_EVERY_STOP {int32 slot}); a freed slot is used
 * again, the lowest first, once the simulator has read the stop: the reply to the next waiting
 * call. Until then the handler stays in its slot (isr_stopping), as the requests queued before the
 * stop, and the stop itself, may let time pass (--mcu-time charges each before it acts) and run it
 * then: it was due before it was stopped; set up
 * again meanwhile (a kit's timer given a new period in its handler), it takes that slot again.
 * spinner_stop_every_latched (a kit's timer whose own interrupt enable is cleared) stops it as an
 * NVIC source: a call that fell due and has not run keeps its pending bit (OP_EVERY_STOP_LATCHED {int32
 * slot, byte 1}; byte 0 where none can be pending: a stop) and runs at the unmask, or after the running handler; the slot is kept (isr_latched) until
 * a reply unmasked and outside handlers, when no such call is left; spinner_unpend_every clears the
 * bit (OP_EVERY_UNPEND {int32 slot}: NVIC_ClearPendingIRQ). spinner_pend_every sets a handler's
 * pending bit (OP_PEND {int32 slot}: NVIC_SetPendingIRQ), in a slot kept as a latched one unless
 * the handler has a running one; unmasked and outside handlers it is a waiting call (OP_PEND_WAIT),
 * which the handler runs in. spinner_every_pending asks whether a handler's call fell due and has not
 * run (OP_EVERY_PENDING {int32 slot...} -> int32: NVIC_GetPendingIRQ), no time passing; it asks only
 * when one can be: masked after time passed, or in a handler (else 0 without a round trip). */
#define MAX_ISRS 32
static void (*isr_fn[MAX_ISRS])(void);
static unsigned char isr_stopping[MAX_ISRS];  /* stopped, the stop not yet read by the simulator */
static unsigned char isr_latched[MAX_ISRS];   /* stopped, a pending call of it may still run */
static int isr_count;   /* slots in use */
/* Masked interrupts (spinner_disable_interrupts: PRIMASK, a bit): the simulator holds the handlers
 * falling due pending and runs them at the unmask. No time passes before the program's next waiting
 * call, so the mask is sent with it (OP_IRQ_MASK; irq_mask_unsent until then; also at the end of a
 * handler that masked, for the handlers due after it) - an unmask before that sends nothing at all -
 * unless the program's own code lets time pass (--mcu-time: a waiting OP_IRQ_MASK_WAIT, so a
 * handler due before the mask runs before the masked code, not inside its first call). The unmask
 * is a waiting call (the pending handlers run inside it) when time may have passed while masked
 * (irq_held: a waiting call since the mask, or --mcu-time); otherwise none can be pending and it is
 * queued. */
static int irq_masked, irq_held, irq_mask_unsent;
static int irq_unmasking;  /* the unmask's waiting call is being made (the kit's look before it) */
static void *irq_mask_ra;  /* where the program masked (the return address of its call) */
static unsigned char mask_msg[9 + 4096];
/* The mask's message: 1, then the caller's offset in its module (uint64) and the module's path, for
 * the simulator's warning of interrupts left disabled (file:line). */
static void *mask_msg_ra;  /* the return address mask_msg holds (a loop masks at one place) */
static size_t mask_msg_len;
static size_t mask_message(void) {
    if (mask_msg_len != 0 && irq_mask_ra == mask_msg_ra) return mask_msg_len;
    uint64_t off = 0;
    const char *path = "";
    Dl_info info;
    if (irq_mask_ra != NULL && dladdr(irq_mask_ra, &info) && info.dli_fname != NULL) {
        off = (uint64_t)((uintptr_t)irq_mask_ra - (uintptr_t)info.dli_fbase);
        path = info.dli_fname;
    }
    size_t n = strlen(path);
    if (n > sizeof mask_msg - 9) n = sizeof mask_msg - 9;
    mask_msg[0] = 1;
    memcpy(mask_msg + 1, &off, sizeof off);
    memcpy(mask_msg + 9, path, n);
    mask_msg_ra = irq_mask_ra;
    return mask_msg_len = 9 + n;
}
static void send_mask(void) {
    irq_mask_unsent = 0;
    irq_held = 1;  /* time may pass from now on (the waiting call it goes with) */
    queue(OP_IRQ_MASK, mask_msg, mask_message(), NULL, 0);
}
static void *prog_lib;  /* the program's library (dlsym of --isr names) */


static void run_isr(uint32_t slot, double time_s) {
    now_time_s = time_s, now_known = 1;  /* the handler's time (spinner_now: no round trip) */
    if (slot >= MAX_ISRS || isr_fn[slot] == NULL)
        fault_report(0, "the simulator asked for an unknown interrupt handler", NULL);
    if (mcu_report) mcu_mark_s = thread_cpu_s();  /* the handler's own time */
    isr_depth++;
    isr_fn[slot]();
    isr_depth--;
    now_known = 0;
    if (irq_mask_unsent) send_mask();  /* the handler masked: the ones due after it are held */
    queue(OP_ISR_DONE, NULL, 0, NULL, 0);
    flush_out();
}

static int add_isr(void (*handler)(void), double period_s) {
    int32_t slot = 0;  /* its own slot if it is being stopped (a timer's new period), else a free one */
    while (slot < MAX_ISRS && !((isr_stopping[slot] || isr_latched[slot]) && isr_fn[slot] == handler)) slot++;
    if (slot == MAX_ISRS)
        for (slot = 0; slot < MAX_ISRS && isr_fn[slot] != NULL; slot++) {}
    if (slot == MAX_ISRS) return -1;
    isr_fn[slot] = handler;
    isr_stopping[slot] = isr_latched[slot] = 0;
    isr_count++;
    queue(OP_EVERY, &period_s, sizeof period_s, &slot, sizeof slot);
    return 0;
}

/* A reply to a waiting call: the simulator has read every request sent before it, the stops too. */
static void release_stopped(void) {
    for (int slot = 0; slot < MAX_ISRS; slot++)
        if (isr_stopping[slot]) isr_stopping[slot] = 0, isr_fn[slot] = NULL;
    if (!irq_masked && isr_depth == 0)  /* every kept pending call has run by now */
        for (int slot = 0; slot < MAX_ISRS; slot++)
            if (isr_latched[slot]) isr_latched[slot] = 0, isr_fn[slot] = NULL;
}

/* A kit built with the program may define `void spinner_kit_before_wait(void)`: it runs before
 * each request the program waits on (not from inside itself), where the kit reads what the
 * program wrote to its emulated registers since (the TFC kit's timers). */
static void (*kit_before_wait)(void);
static int in_kit_hook;

#ifdef SPINNER_INPROC
/* An exit another thread of the program called (in process): the thread ends there and the
 * program at main()'s thread's next waiting call, with that status, as exit() from a thread
 * ends a process (its exit handlers run, as glibc runs them, on main()'s stack). It cannot end
 * the coroutine from another thread: switching main()'s stack there crashed the simulator's
 * process. -1: none. */
static volatile int thread_exit_status = -1;
static volatile int thread_exit_quick;  /* it was _exit, _Exit or quick_exit: no exit handlers */
static int run_active;  /* (below: a run is on) */
static void exit_run(int status) __attribute__((noreturn));
static void leave(int status) __attribute__((noreturn));
static void thread_exit_check(void) {
    int status = __atomic_exchange_n(&thread_exit_status, -1, __ATOMIC_ACQ_REL);
    if (status < 0 || finished || !in_controller || !pthread_equal(pthread_self(), sim_thread_id)) {
        if (status >= 0) __atomic_store_n(&thread_exit_status, status, __ATOMIC_RELEASE);  /* (kept) */
        return;
    }
    if (thread_exit_quick) leave(status);
    exit_run(status);
}
#else
static void thread_exit_check(void) {}
#endif

/* Send a waiting request and read the reply into `reply` (at most `size` bytes); returns the
 * reply's length. The run being over ends the program. */
static size_t call(uint32_t op, const void *a, size_t na, const void *b, size_t nb,
                   void *reply, size_t size) {
    if (foreign_thread()) {
        if (size) memset(reply, 0, size);
        return 0;
    }
    thread_exit_check();
    /* time passes in the call - but not in OP_NOW, OP_NOW_UNCHARGED or OP_EVERY_PENDING, unless
     * --mcu-time charges it or the calls queued before it (main() only) */
    int passes = (op != OP_NOW && op != OP_NOW_UNCHARGED && op != OP_EVERY_PENDING)
                 || (mcu_on && isr_depth == 0);
    if (kit_before_wait != NULL && !in_kit_hook && passes) {  /* (the kit's registers before time passes) */
        in_kit_hook = 1;
        kit_before_wait();
        in_kit_hook = 0;
    }
    /* time passes while masked: handlers may be held pending (then the mask went at once) */
    if (passes && irq_mask_unsent) send_mask();
    if (passes && irq_masked) irq_held = 1;
    queue(op, a, na, b, nb);
    flush_out();
    uint32_t hdr[2];
    size_t have = read_reply_head(hdr, reply, size);  /* have <= size */
    while (hdr[0] == ST_ISR) {  /* an interrupt first (its slot and time: 12 bytes, maybe read already) */
        unsigned char isr[12];
        size_t c = have < sizeof isr ? have : sizeof isr;
        if (c) memcpy(isr, reply, c);
        if (c < sizeof isr) read_all(isr + c, sizeof isr - c);
        uint32_t slot;
        double time_s;
        memcpy(&slot, isr, sizeof slot);
        memcpy(&time_s, isr + sizeof slot, sizeof time_s);
        run_isr(slot, time_s);
        have = read_reply_head(hdr, reply, size);
    }
    release_stopped();
    now_known = 0;  /* time may have passed */
    if (passes && irq_masked) irq_held = 1;  /* (masked by a handler that ran in it) */
    if (hdr[0] == ST_FINISHED) {
        finished = run_over = 1;
        ended();
    }
    if (hdr[0] == ST_WHERE) fault_report(SIGUSR1, "", NULL);
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
    if (mcu_report) mcu_mark_s = thread_cpu_s();  /* the program's own time starts again */
    thread_exit_check();  /* (one called while this call waited) */
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

void spinner_fail(const char *message) {
#ifdef SPINNER_INPROC
    if (opening) load_ended("spinner_fail", -1, message ? message : "");
#endif
    INIT();
    misuse("%s", message);
    for (;;) pause();  /* not reached: the report ends the run */
}

/* The API function the foreign thread called (its outermost frame in this module: the host is
 * built with -fno-optimize-sibling-calls, so the entry point keeps its frame) as ", NAME()," into
 * `out`; "" when it has no symbol. The sleeps' --wrap names are the program's: usleep. */
static void foreign_call_name(char *out, size_t size) {
    Dl_info here, info;
    out[0] = 0;
    if (!dladdr((void *)foreign_call_name, &here)) return;
    int entry = -1;
    for (int i = 0; i < foreign_depth; i++) {
        if (!dladdr(foreign_frames[i], &info) || info.dli_fbase != here.dli_fbase) break;
        entry = i;
    }
    const ElfW(Sym) *sym = NULL;
    if (entry < 0 || !dladdr1((char *)foreign_frames[entry] - 1, &info, (void **)&sym, RTLD_DL_SYMENT) ||
        info.dli_sname == NULL || sym == NULL)
        return;
    uintptr_t at = (uintptr_t)foreign_frames[entry] - 1, start = (uintptr_t)info.dli_saddr;
    if (at < start || at >= start + sym->st_size) return;  /* (a static function: not a name of the API) */
    const char *name = info.dli_sname;
    if (strncmp(name, "__wrap_", 7) == 0) name += 7;
    snprintf(out, size, ", %s(),", name);
}

static void foreign_report(const char *message);
static void foreign_call_report(void) {
    __atomic_store_n(&foreign_calls, FOREIGN_REPORTED, __ATOMIC_RELEASE);  /* (once; the frames stay) */
    char call[160];
    foreign_call_name(call, sizeof call);
    static char msg[1024];
    if (foreign_message[0])
        snprintf(msg, sizeof msg, "a Spinner call%s came from another thread than the one running main() and "
                 "ended that thread (%s): the API answers main()'s thread only; hand the values to that thread "
                 "instead", call, foreign_message);
    else
        snprintf(msg, sizeof msg, "a Spinner call%s came from another thread than the one running main() (it "
                 "returned 0): the API answers main()'s thread only; hand the values to that thread instead", call);
    foreign_report(msg);
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
    double cmd[3] = {set_speed ? speed_mps : NAN, steer_rad, yaw};  /* NaN: steering only (motors kept) */
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

/* The bytes an image of `line` (-1: all rows) takes; a bad row or a short buffer is misuse of `fn`. */
static size_t image_bytes(const char *fn, int line, const uint8_t *buf, size_t size) {
    if (line < -1 || line >= img_h)
        misuse("%s(line=%d): expected -1 (whole image) or a row 0..%d", fn, line, img_h - 1);
    size_t need = line < 0 ? (size_t)img_h * img_w : (size_t)img_w;
    if (buf == NULL || size < need)
        misuse("%s(line=%d, size=%zu): the buffer must hold %zu bytes", fn, line, size, need);
    return need;
}

size_t spinner_get_image(int line, int add_noise, uint8_t *buf, size_t size) {
    INIT();
    image_bytes("spinner_get_image", line, buf, size);
    if (finished) return 0;
    int32_t args[2] = {line, add_noise ? 1 : 0};
    return call(OP_IMAGE, args, sizeof args, NULL, 0, buf, size);
}

long long spinner_latest_image(int line, int add_noise, long long after_frame, uint8_t *buf, size_t size,
                               size_t *written) {
    static unsigned char *reply;  /* the frame's index (int64), then its image */
    static size_t reply_size;
    INIT();
    if (written) *written = 0;
    size_t need = image_bytes("spinner_latest_image", line, buf, size);
    if (finished) return after_frame;
    if (reply_size < 8 + need) {
        free(reply);
        reply = malloc(8 + need);
        if (reply == NULL) misuse("spinner_latest_image: out of memory");
        reply_size = 8 + need;
    }
    struct { int32_t line, noise; int64_t after; } args = {line, add_noise ? 1 : 0, after_frame};
    size_t n = call(OP_LATEST_IMAGE, &args, sizeof args, NULL, 0, reply, 8 + need);
    int64_t frame;
    memcpy(&frame, reply, sizeof frame);
    if (n > 8) {
        memcpy(buf, reply + 8, n - 8);
        if (written) *written = n - 8;
    }
    return frame;
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

double spinner_get_distance(const char *name) {
    static double last_distance_m;
    INIT();
    if (name == NULL) misuse("spinner_get_distance(name=NULL): expected a range sensor's name");
    if (!finished) call(OP_DISTANCE, NULL, 0, name, strlen(name), &last_distance_m, sizeof last_distance_m);
    return last_distance_m;
}

static int get_scan(const char *call_name, unsigned char flag, const char *name, double *out, int max_rays) {
    static double buf[4096];
    static int last_n;
    INIT();
    if (name == NULL) misuse("%s(name=NULL): expected a lidar's name", call_name);
    if (max_rays < 0 || (out == NULL && max_rays > 0))
        misuse("%s(\"%s\", out=%p, max_rays=%d): expected room for max_rays >= 0 values", call_name, name,
               (void *)out, max_rays);
    if (!finished) last_n = (int)(call(OP_SCAN, &flag, 1, name, strlen(name), buf, sizeof buf) / sizeof(double));
    int n = last_n < max_rays ? last_n : max_rays;
    if (n > 0) memcpy(out, buf, (size_t)n * sizeof(double));
    return last_n;
}

int spinner_get_scan(const char *name, double *ranges_m, int max_rays) {
    return get_scan("spinner_get_scan", 0, name, ranges_m, max_rays);
}

int spinner_get_scan_angles(const char *name, double *angles_rad, int max_rays) {
    return get_scan("spinner_get_scan_angles", 1, name, angles_rad, max_rays);
}

void spinner_set_motors(float left, float right) {
    INIT();
    double duty[2] = {finite_arg("spinner_set_motors", "left", left), finite_arg("spinner_set_motors", "right", right)};
    if (!finished) queue(OP_MOTORS, duty, sizeof duty, NULL, 0);
}

long long spinner_get_encoder(int wheel) {
    static long long last[4];
    INIT();
    if (wheel < 0 || wheel > 3)
        misuse("spinner_get_encoder(%d): expected a wheel, SPINNER_WHEEL_FL (0) .. SPINNER_WHEEL_RR (3)", wheel);
    int32_t w = wheel;
    if (!finished) call(OP_ENCODER, &w, sizeof w, NULL, 0, &last[wheel], sizeof last[wheel]);
    return last[wheel];
}

int spinner_encoder_lines(int wheel, int *counts_per_line) {
    INIT();
    int fitted = wheel >= 0 && wheel < 4 && ((encoder_mask >> wheel) & 1);
    if (counts_per_line) *counts_per_line = fitted ? encoder_per_line : 0;
    return fitted ? encoder_lines : 0;
}

int spinner_has_imu(void) { INIT(); return has_imu; }

static void get_imu(unsigned char flag, double *x, double *y, double *z) {
    static double last[2][3];
    INIT();
    if (!finished) call(OP_IMU, &flag, 1, NULL, 0, last[flag], sizeof last[flag]);
    if (x) *x = last[flag][0];
    if (y) *y = last[flag][1];
    if (z) *z = last[flag][2];
}

void spinner_get_gyro(double *x_radps, double *y_radps, double *z_radps) { get_imu(0, x_radps, y_radps, z_radps); }
void spinner_get_accel(double *x_mps2, double *y_mps2, double *z_mps2) { get_imu(1, x_mps2, y_mps2, z_mps2); }

double spinner_get_time(void) {
    INIT();
    if (!finished) call(OP_TIME, NULL, 0, NULL, 0, &last_time_s, sizeof last_time_s);
    return last_time_s;
}

/* The time as the program's last charged call left it (or a handler's time), asked with `op` once
 * after each call that may let time pass (now_known). */
static double known_time(uint32_t op) {
    if (!now_known) {
        call(op, NULL, 0, NULL, 0, &now_time_s, sizeof now_time_s);
        now_known = 1;
    }
    return now_time_s;
}

/* A read of the time. With --mcu-time, main()'s read is a request as charged as any: the program's
 * time since its previous charged call passes first (a handler due in it runs before the read
 * returns, as an interrupt before the instruction), so each read is a round trip and a loop that
 * polls the time - or a kit's timer register, whose count the kit makes with it - lets time pass:
 * on the MCU such a loop spends its time reading. Without it, and in a handler, as
 * spinner_now_uncharged (sent as OP_NOW). */
double spinner_now(void) {
    INIT();
    if (finished) return last_time_s;
    if (mcu_on && isr_depth == 0) {
        call(OP_NOW, NULL, 0, NULL, 0, &now_time_s, sizeof now_time_s);
        now_known = 1;
        return now_time_s;
    }
    return known_time(OP_NOW);
}

double spinner_now_uncharged(void) {
    INIT();
    if (finished) return last_time_s;
    return known_time(OP_NOW_UNCHARGED);
}

void spinner_set_exposure(double seconds) {
    INIT();
    if (!isfinite(seconds)) misuse("spinner_set_exposure(seconds=%g): expected a finite number", seconds);
    if (finished) return;
    call(OP_SET_EXPOSURE, &seconds, sizeof seconds, NULL, 0, NULL, 0);
}

void spinner_set_exposure_next_frame(double seconds) {
    INIT();
    if (!isfinite(seconds)) misuse("spinner_set_exposure_next_frame(seconds=%g): expected a finite number", seconds);
    if (finished) return;
    call(OP_SET_EXPOSURE_NEXT, &seconds, sizeof seconds, NULL, 0, NULL, 0);
}

void spinner_camera_free_running(void) {
    INIT();
    if (finished) return;
    call(OP_FREE_RUNNING, NULL, 0, NULL, 0, NULL, 0);
}

double spinner_get_exposure(void) {
    static double last_exposure_s;
    INIT();
    if (!finished) call(OP_GET_EXPOSURE, NULL, 0, NULL, 0, &last_exposure_s, sizeof last_exposure_s);
    return last_exposure_s;
}

/* -- the Pixy2 (pixy2_line.h): requests answered by simrunner.run.pixy2 ------------------ */
enum { PIXY_SET_MODE = 1, PIXY_SET_NEXT_TURN, PIXY_SET_DEFAULT_TURN, PIXY_SET_VECTOR,
       PIXY_REVERSE_VECTOR, PIXY_SET_BRIGHTNESS, PIXY_INIT, PIXY_SET_LAMP, PIXY_GET_RESOLUTION };

static int8_t pixy_set(int32_t what, int32_t value) {
    int32_t req[2] = {what, value}, result = PIXY_RESULT_OK;
    INIT();
    if (finished) return PIXY_RESULT_OK;
    call(OP_PIXY_SET, req, sizeof req, NULL, 0, &result, sizeof result);
    return (int8_t)result;
}

int8_t pixy2_init(void) { return pixy_set(PIXY_INIT, 0); }
int8_t pixy2_line_set_mode(uint8_t mode) { return pixy_set(PIXY_SET_MODE, mode); }
int8_t pixy2_line_set_next_turn(int16_t angle) { return pixy_set(PIXY_SET_NEXT_TURN, angle); }
int8_t pixy2_line_set_default_turn(int16_t angle) { return pixy_set(PIXY_SET_DEFAULT_TURN, angle); }
int8_t pixy2_line_set_vector(uint8_t index) { return pixy_set(PIXY_SET_VECTOR, index); }
int8_t pixy2_line_reverse_vector(void) { return pixy_set(PIXY_REVERSE_VECTOR, 0); }
int8_t pixy2_set_camera_brightness(uint8_t brightness) { return pixy_set(PIXY_SET_BRIGHTNESS, brightness); }
int8_t pixy2_set_lamp(uint8_t upper, uint8_t lower) { return pixy_set(PIXY_SET_LAMP, upper << 8 | lower); }

int8_t pixy2_get_resolution(uint16_t *width, uint16_t *height) {
    int8_t result = pixy_set(PIXY_GET_RESOLUTION, 0);  /* (a request, as the library's: --mcu-time charges it) */
    if (width) *width = (uint16_t)img_w;
    if (height) *height = (uint16_t)img_h;
    return result;
}

int8_t pixy2_change_prog(const char *prog) {
    int32_t result = PIXY_RESULT_OK;
    INIT();
    if (prog == NULL) misuse("pixy2_change_prog(prog=NULL): expected a program name (\"line\")");
    if (finished) return PIXY_RESULT_OK;
    call(OP_PIXY_PROG, prog, strlen(prog), NULL, 0, &result, sizeof result);
    return (int8_t)result;
}

/* The reply: int32 result, int32 counts (vectors, intersections, barcodes), then the three
 * arrays in the layouts of pixy2_line.h. */
static struct {
    int32_t head[4];
    pixy2_vector vectors[255];
    pixy2_intersection intersections[255];
    pixy2_barcode barcodes[255];
} pixy_reply;

static int8_t pixy_features(int32_t main_features, uint8_t features, bool wait, pixy2_line_features *out) {
    static unsigned char buf[sizeof pixy_reply];
    int32_t req[3] = {main_features, features, wait ? 1 : 0};
    INIT();
    if (out == NULL) misuse("pixy2_line_get_%s_features(out=NULL): expected a pixy2_line_features to fill",
                            main_features ? "main" : "all");
    if (finished) {
        memset(out, 0, sizeof *out);
        return 0;
    }
    size_t n = call(OP_PIXY_FEATURES, req, sizeof req, NULL, 0, buf, sizeof buf);
    int32_t head[4] = {0, 0, 0, 0};
    memcpy(head, buf, n < sizeof head ? n : sizeof head);  /* BUSY: the result alone */
    if (head[0] == PIXY_RESULT_BUSY) return PIXY_RESULT_BUSY;
    size_t nv = (size_t)head[1], ni = (size_t)head[2], nb = (size_t)head[3];
    const unsigned char *p = buf + sizeof head;
    memcpy(pixy_reply.vectors, p, nv * sizeof(pixy2_vector));
    p += nv * sizeof(pixy2_vector);
    memcpy(pixy_reply.intersections, p, ni * sizeof(pixy2_intersection));
    p += ni * sizeof(pixy2_intersection);
    memcpy(pixy_reply.barcodes, p, nb * sizeof(pixy2_barcode));
    out->numVectors = (uint8_t)nv, out->vectors = pixy_reply.vectors;
    out->numIntersections = (uint8_t)ni, out->intersections = pixy_reply.intersections;
    out->numBarcodes = (uint8_t)nb, out->barcodes = pixy_reply.barcodes;
    return (int8_t)head[0];
}

int8_t pixy2_line_get_main_features(uint8_t features, bool wait, pixy2_line_features *out) {
    return pixy_features(1, features, wait, out);
}

int8_t pixy2_line_get_all_features(uint8_t features, bool wait, pixy2_line_features *out) {
    return pixy_features(0, features, wait, out);
}

int spinner_interrupts(void) {
    INIT();
    return isr_count;
}

int spinner_in_interrupt(void) { return isr_depth > 0; }

#ifdef SPINNER_INPROC
int spinner_running(void) {
    if (opening) {  /* (a kit that would have asked: as a call, INIT) */
        early_calls = 1;
        return 0;
    }
    return in_controller;
}
#else
int spinner_running(void) { return 1; }  /* (the pipes are there before the library is loaded) */
#endif

void spinner_every(double period_s, void (*handler)(void)) {
    INIT();
    if (handler == NULL) misuse("spinner_every(period_s=%g, handler=NULL): expected a function", period_s);
    if (!(period_s >= 1e-5) || !isfinite(period_s))
        misuse("spinner_every(period_s=%g): expected at least 1e-05 s (a 100 kHz timer)", period_s);
    if (finished) return;
    if (add_isr(handler, period_s) < 0) misuse("spinner_every: at most %d interrupt handlers", MAX_ISRS);
}

void spinner_stop_every(void (*handler)(void)) {
    INIT();
    if (finished || handler == NULL) return;
    for (int32_t slot = 0; slot < MAX_ISRS; slot++) {
        if (isr_fn[slot] != handler || isr_stopping[slot]) continue;
        if (isr_latched[slot]) {  /* stopped already: its kept call goes too (the slot stays until release) */
            queue(OP_EVERY_UNPEND, &slot, sizeof slot, NULL, 0);
            continue;
        }
        isr_stopping[slot] = 1;
        isr_count--;
        queue(OP_EVERY_STOP, &slot, sizeof slot, NULL, 0);
    }
}

void spinner_stop_every_latched(void (*handler)(void)) {
    INIT();
    if (finished || handler == NULL) return;
    /* a call can be pending only if time passed while masked (a waiting call, or with --mcu-time any
     * request), or in a handler (one due at its step) */
    int may_pend = (irq_masked && (irq_held || mcu_on)) || irq_unmasking || isr_depth > 0;
    for (int32_t slot = 0; slot < MAX_ISRS; slot++) {
        if (isr_fn[slot] != handler || isr_stopping[slot] || isr_latched[slot]) continue;
        unsigned char latch = (unsigned char)may_pend;
        if (may_pend) isr_latched[slot] = 1;
        else isr_stopping[slot] = 1;
        isr_count--;
        queue(OP_EVERY_STOP_LATCHED, &slot, sizeof slot, &latch, 1);
    }
}

void spinner_pend_every(void (*handler)(void)) {
    INIT();
    if (finished || handler == NULL) return;
    int32_t slot = 0;  /* its running slot, else its kept one, else a free one (kept until it has run) */
    while (slot < MAX_ISRS && !(isr_fn[slot] == handler && !isr_stopping[slot] && !isr_latched[slot])) slot++;
    if (slot == MAX_ISRS)
        for (slot = 0; slot < MAX_ISRS && !(isr_latched[slot] && isr_fn[slot] == handler); slot++) {}
    if (slot == MAX_ISRS) {
        for (slot = 0; slot < MAX_ISRS && isr_fn[slot] != NULL; slot++) {}
        if (slot == MAX_ISRS) misuse("spinner_pend_every: at most %d interrupt handlers", MAX_ISRS);
        isr_fn[slot] = handler, isr_latched[slot] = 1;
    }
    if (irq_masked || isr_depth > 0 || in_kit_hook) {  /* runs at the unmask, after the handler, or in */
        if (irq_masked && irq_mask_unsent) send_mask();  /* the waiting call the kit's look precedes */
        if (irq_masked) irq_held = 1;  /* (the unmask then waits: it runs in it) */
        queue(OP_PEND, &slot, sizeof slot, NULL, 0);
    } else {
        call(OP_PEND_WAIT, &slot, sizeof slot, NULL, 0, NULL, 0);
    }
}

void spinner_unpend_every(void (*handler)(void)) {
    INIT();
    if (finished || handler == NULL) return;
    for (int32_t slot = 0; slot < MAX_ISRS; slot++)
        if (isr_latched[slot] && isr_fn[slot] == handler) queue(OP_EVERY_UNPEND, &slot, sizeof slot, NULL, 0);
}

int spinner_every_pending(void (*handler)(void)) {
    INIT();
    if (finished || handler == NULL) return 0;
    /* held by the mask only if time passed while masked (a waiting call, or with --mcu-time any
     * request); due after the running handler only in one (as spinner_stop_every_latched) */
    if (!((irq_masked && (irq_held || mcu_on)) || irq_unmasking || isr_depth > 0)) return 0;
    int32_t slots[MAX_ISRS], n = 0;  /* its running and kept slots (a stopping one's calls are gone) */
    for (int32_t slot = 0; slot < MAX_ISRS; slot++)
        if (isr_fn[slot] == handler && !isr_stopping[slot]) slots[n++] = slot;
    if (n == 0) return 0;
    int32_t pending = 0;
    call(OP_EVERY_PENDING, slots, (size_t)n * sizeof slots[0], NULL, 0, &pending, sizeof pending);
    return pending != 0;
}

static void set_mask(int masked) {
    unsigned char flag = (unsigned char)masked;
    if (finished || masked == irq_masked) return;  /* a bit: a second disable changes nothing */
    if (masked) {  /* (the handlers due before it run in the waiting one, unmasked) */
        if (mcu_on && isr_depth == 0) call(OP_IRQ_MASK_WAIT, mask_msg, mask_message(), NULL, 0, NULL, 0);
        else irq_mask_unsent = 1;
        irq_masked = 1, irq_held = 0;
    } else if (irq_mask_unsent) {  /* nothing passed while masked: the simulator need not know */
        irq_mask_unsent = irq_masked = 0;
    } else {
        int held = irq_held || (mcu_on && isr_depth == 0);
        irq_masked = irq_held = 0;
        if (held && isr_depth == 0) {
            irq_unmasking = 1;  /* (a kit timer its look before the call stops may have a call pending) */
            call(OP_IRQ_MASK_WAIT, &flag, 1, NULL, 0, NULL, 0);
            irq_unmasking = 0;
        } else {
            queue(OP_IRQ_MASK, &flag, 1, NULL, 0);  /* (in a handler: they run after it) */
        }
    }
}

void spinner_disable_interrupts(void) {
    INIT();
    if (!irq_masked) irq_mask_ra = __builtin_return_address(0);
    set_mask(1);
}

void spinner_enable_interrupts(void) {
    INIT();
    set_mask(0);
}

int spinner_interrupts_disabled(void) { return irq_masked; }

int spinner_has_every(void (*handler)(void)) {
    INIT();
    for (int slot = 0; slot < MAX_ISRS; slot++)
        if (handler != NULL && isr_fn[slot] == handler && !isr_stopping[slot] && !isr_latched[slot]) return 1;
    return 0;
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
    if (finished || OPENING()) return default_value;
    double v;
    call(OP_PARAM, &default_value, sizeof default_value, name, strlen(name), &v, sizeof v);
    return v;
}

/* -- sleeping in simulated time ------------------------------------------------------------ */
static int sim_usleep(useconds_t usec) {
    spinner_sleep(usec * 1e-6);
    return 0;
}

static unsigned int sim_sleep(unsigned int seconds) {
    spinner_sleep((double)seconds);
    return 0;
}

static int sim_nanosleep(const struct timespec *req, struct timespec *rem) {
    if (req == NULL || req->tv_nsec < 0 || req->tv_nsec >= 1000000000L || req->tv_sec < 0) {
        errno = EINVAL;
        return -1;
    }
    spinner_sleep((double)req->tv_sec + req->tv_nsec * 1e-9);
    if (rem) rem->tv_sec = 0, rem->tv_nsec = 0;
    return 0;
}

static int sim_clock_nanosleep(clockid_t clock, int flags, const struct timespec *req,
                               struct timespec *rem) {
    (void)clock;
    if (req == NULL || req->tv_nsec < 0 || req->tv_nsec >= 1000000000L) return EINVAL;
    double s = (double)req->tv_sec + req->tv_nsec * 1e-9;
    if (flags & TIMER_ABSTIME) s -= spinner_get_time();  /* absolute: on the simulated clock */
    spinner_sleep(s > 0 ? s : 0);
    if (rem) rem->tv_sec = 0, rem->tv_nsec = 0;
    return 0;
}

/* What controllers built by simrunner call (linked with --wrap=usleep,...; build.py). */
int __wrap_usleep(useconds_t usec) { return sim_usleep(usec); }
unsigned int __wrap_sleep(unsigned int seconds) { return sim_sleep(seconds); }
int __wrap_nanosleep(const struct timespec *req, struct timespec *rem) {
    return sim_nanosleep(req, rem);
}
int __wrap_clock_nanosleep(clockid_t clock, int flags, const struct timespec *req,
                           struct timespec *rem) {
    return sim_clock_nanosleep(clock, flags, req, rem);
}

/* Where the program called exit (or _exit, _Exit, quick_exit): OP_EXIT_AT, queued with the run's
 * last requests, so the run's outcome names the line as a Python controller's sys.exit is named
 * ("the controller called exit(3) at main.c:91"): which call (uint8: 0 exit, 1 _exit, 2 _Exit, 3
 * quick_exit; + EXIT_AT_LOAD from a constructor as an isolated host opens the library), the status
 * (int32), the caller's return address as its offset in its module (uint64) and the module's path.
 * Not from a process the program forked, nor after the run. */
#define EXIT_AT_LOAD 0x80  /* OP_EXIT_AT's call byte: the exit was in a constructor as the library loaded */
static void exit_note(uint8_t fn, int status, void *ra) {
    if (forked) return;
    Dl_info host, caller;  /* the host's own end (main returned: exit(0); a report's _exit) is no call of the program's */
    if (ra != NULL && dladdr((void *)exit_note, &host) && dladdr(ra, &caller) && host.dli_fbase == caller.dli_fbase)
        return;
#ifdef SPINNER_INPROC
    /* (finished is set while the program's exit handlers run too: an exit there, an atexit
     * handler's or a static destructor's, is the status the program ends with, as it is
     * isolated; after the simulator ended the run, none is) */
    if (run_over || !in_controller || !pthread_equal(pthread_self(), sim_thread_id)) return;
#else
    if (finished) return;
#endif
    INIT();
    if (foreign_thread()) return;
    unsigned char msg[1 + 4 + 8 + 4096];
    int32_t st = status;
    uint64_t off = 0;
    const char *path = "";
    Dl_info info;
    if (ra != NULL && dladdr(ra, &info) && info.dli_fname != NULL) {
        off = (uint64_t)((uintptr_t)ra - (uintptr_t)info.dli_fbase);
        path = info.dli_fname;
    }
    size_t n = strlen(path);
    if (n > sizeof msg - 13) n = sizeof msg - 13;
    msg[0] = fn;
    memcpy(msg + 1, &st, sizeof st);
    memcpy(msg + 5, &off, sizeof off);
    memcpy(msg + 13, path, n);
#ifndef SPINNER_INPROC
    if (loading) msg[0] |= EXIT_AT_LOAD;  /* (in a constructor: said so, as in process) */
#endif
    queue_raw(OP_EXIT_AT, msg, 13 + n, NULL, 0);
    flush_out();
}
#define EXIT_NOTE(fn, status) exit_note(fn, status, __builtin_return_address(0))

#ifndef SPINNER_INPROC
/* The host program also interposes the real names (a prebuilt library's references). */
int usleep(useconds_t usec) { return sim_usleep(usec); }
unsigned int sleep(unsigned int seconds) { return sim_sleep(seconds); }
int nanosleep(const struct timespec *req, struct timespec *rem) { return sim_nanosleep(req, rem); }
int clock_nanosleep(clockid_t clock, int flags, const struct timespec *req, struct timespec *rem) {
    return sim_clock_nanosleep(clock, flags, req, rem);
}

/* exit and friends end the host process as they would end the program; its exit handlers are
 * the process's own (atexit, static destructors: glibc runs them). A prebuilt library's calls (not
 * linked with --wrap) come to the host program's own exit, _exit, _Exit and quick_exit (exported,
 * first in the lookup), which note the call as the --wrap ones do (its place: a file:line with
 * debug info, else the function, simrunner's symbolize) and go on to libc's (LIBC_EXIT). The host's
 * own calls are no program's: exit_note leaves them out. */
#define LIBC_EXIT(name, status)                                         \
    do {                                                                \
        static void (*real)(int);                                       \
        if (real == NULL) real = (void (*)(int))dlsym(RTLD_NEXT, name); \
        if (real != NULL) real(status);                                 \
        syscall(SYS_exit_group, status); /* (no libc's: not reached) */ \
        __builtin_unreachable();                                        \
    } while (0)
static void ended(void) { exit(0); }
void __wrap_exit(int status) { EXIT_NOTE(0, status); LIBC_EXIT("exit", status); }
void __wrap__exit(int status) { EXIT_NOTE(1, status); LIBC_EXIT("_exit", status); }
void __wrap__Exit(int status) { EXIT_NOTE(2, status); LIBC_EXIT("_Exit", status); }
void __wrap_quick_exit(int status) { EXIT_NOTE(3, status); LIBC_EXIT("quick_exit", status); }
void exit(int status) { EXIT_NOTE(0, status); LIBC_EXIT("exit", status); }
void _exit(int status) { EXIT_NOTE(1, status); LIBC_EXIT("_exit", status); }
void _Exit(int status) { EXIT_NOTE(2, status); LIBC_EXIT("_Exit", status); }
void quick_exit(int status) { EXIT_NOTE(3, status); LIBC_EXIT("quick_exit", status); }
int __wrap_atexit(void (*fn)(void)) { return atexit(fn); }
int __cxa_atexit(void (*fn)(void *), void *arg, void *dso);
int __wrap___cxa_atexit(void (*fn)(void *), void *arg, void *dso) { return __cxa_atexit(fn, arg, dso); }
#else
/* In-process the program's exit ends its coroutine with that status (not the simulator). */
static void leave(int status) {
    finished = 1;
    fflush(stdout);
    fflush(stderr);
    if (forked) _exit(status);  /* a process the controller forked (below) ends here */
    exit_code = status & 0xff;  /* as a process's exit status: exit(-2) is 254, not a signal */
    gone = 1;
    in_controller = 0;
    pthread_sigmask(SIG_SETMASK, &run_mask, NULL);  /* from a handler: unblock its signal */
    ESCAPE();
    abort();  /* not reached */
}
/* In the simulator's process the program's exit handlers (atexit, a C++ program's static
 * destructors: __cxa_atexit) are kept here and run, last registered first, when the program
 * ends as exit() ends one (main returns, exit, the run's end), with its stdio flushed; _exit,
 * _Exit, quick_exit and faults skip them, as they do on a real system. A fault or a run ended
 * by the simulator drops the rest (spinner_inproc_finish). Each handler is its library's: the one
 * being loaded by the registering thread (its constructors' registrations: tagged with the handle
 * when the load returns), else the running program's - a program's end runs its own only (another
 * program opened ahead of its run keeps its static destructors for its own end). */
#define MAX_EXIT_HANDLERS 256
static struct { void (*fn)(void *); void *arg; void *lib; } exit_handlers[MAX_EXIT_HANDLERS];
static int n_exit_handlers;
static pthread_mutex_t exit_lock = PTHREAD_MUTEX_INITIALIZER;
#define LOADING_TAG ((void *)&opening)  /* (a thread-local's address: this thread's load) */
static void call_plain(void *fn) { ((void (*)(void))fn)(); }
static int add_exit_handler(void (*fn)(void *), void *arg) {
    int ok = 0;
    pthread_mutex_lock(&exit_lock);
    if (n_exit_handlers < MAX_EXIT_HANDLERS) {
        exit_handlers[n_exit_handlers].fn = fn;
        exit_handlers[n_exit_handlers].arg = arg;
        exit_handlers[n_exit_handlers++].lib = opening ? LOADING_TAG : prog_lib;
        ok = 1;
    }
    pthread_mutex_unlock(&exit_lock);
    return ok ? 0 : -1;
}
/* The handlers of `from` become `to`'s (NULL: dropped). */
static void retag_exit_handlers(void *from, void *to) {
    pthread_mutex_lock(&exit_lock);
    int kept = 0;
    for (int i = 0; i < n_exit_handlers; i++) {
        if (exit_handlers[i].lib == from) {
            if (to == NULL) continue;
            exit_handlers[i].lib = to;
        }
        exit_handlers[kept++] = exit_handlers[i];
    }
    n_exit_handlers = kept;
    pthread_mutex_unlock(&exit_lock);
}
/* Take `lib`'s last registered handler (1), or none is left (0). */
static int take_exit_handler(void *lib, void (**fn)(void *), void **arg) {
    int found = 0;
    pthread_mutex_lock(&exit_lock);
    for (int i = n_exit_handlers - 1; i >= 0 && !found; i--) {
        if (exit_handlers[i].lib != lib) continue;
        *fn = exit_handlers[i].fn, *arg = exit_handlers[i].arg;
        for (int k = i + 1; k < n_exit_handlers; k++) exit_handlers[k - 1] = exit_handlers[k];
        n_exit_handlers--;
        found = 1;
    }
    pthread_mutex_unlock(&exit_lock);
    return found;
}
int __wrap_atexit(void (*fn)(void)) { return add_exit_handler(call_plain, (void *)fn); }
int __wrap___cxa_atexit(void (*fn)(void *), void *arg, void *dso) {
    (void)dso;
    return add_exit_handler(fn, arg);
}
/* Its library's destructors (a C function marked __attribute__((destructor)), what its
 * .fini_array holds) are taken from it when its run starts (take_fini: the entries are
 * replaced by a no-op, so unloading the library later runs none of them) and run here, after
 * the exit handlers, last first, as exit() runs a program's. */
#define MAX_FINI 256
static void (*fini_fns[MAX_FINI])(void);
static int n_fini;
static void exit_run(int status) {
    finished = 1;  /* Spinner calls from the handlers return at once */
    void (*fn)(void *);
    void *arg;
    while (take_exit_handler(prog_lib, &fn, &arg)) fn(arg);
    while (n_fini > 0) fini_fns[--n_fini]();
    fflush(NULL);
    leave(status);
}
static void ended(void) { exit_run(0); }
/* From a thread other than the simulator's (a thread the program started): see thread_exit_status. */
static void thread_exit(int status, int quick) {
    if (forked || pthread_equal(pthread_self(), sim_thread_id)) return;
    if (__atomic_load_n(&run_active, __ATOMIC_ACQUIRE) && !finished) {
        thread_exit_quick = quick;
        __atomic_store_n(&thread_exit_status, status & 0xff, __ATOMIC_RELEASE);
    }
    pthread_exit(NULL);
}
#define AT_LOAD(fn, status) do { if (opening) load_ended(fn, status, NULL); } while (0)
void __wrap_exit(int status) { AT_LOAD("exit", status); thread_exit(status, 0); EXIT_NOTE(0, status); exit_run(status); }
void __wrap__exit(int status) { AT_LOAD("_exit", status); thread_exit(status, 1); EXIT_NOTE(1, status); leave(status); }
void __wrap__Exit(int status) { AT_LOAD("_Exit", status); thread_exit(status, 1); EXIT_NOTE(2, status); leave(status); }
void __wrap_quick_exit(int status) { AT_LOAD("quick_exit", status); thread_exit(status, 1); EXIT_NOTE(3, status); leave(status); }
#endif

/* -- fork ------------------------------------------------------------------------------- */
/* A process the controller fork()s (linked with --wrap=fork; the host program also catches a
 * prebuilt library's forks with pthread_atfork) is a helper of the program, not the program:
 * it has no simulator to talk to (in-process its memory holds a copy of the simulator, which
 * must never run twice: it would write the run's frames again). Its Spinner calls end it
 * with a message (exit status 70); its exit, _exit and faults end it as they end a process;
 * it ends with the run (in-process the run's end kills it; the simulator's or the host
 * program's death does too: PR_SET_PDEATHSIG). */
#define FORK_EXIT 70
static pid_t fork_parent;

static void forked_call(void) {
    char msg[320];
    int n = snprintf(msg, sizeof msg,
                     "simrunner: a Spinner call in process %ld, which the controller fork()ed from "
                     "process %ld: only the controller's own process drives the car; this one ends "
                     "(exit status %d)\n", (long)getpid(), (long)fork_parent, FORK_EXIT);
    if (n > 0) {
        ssize_t w = write(2, msg, (size_t)n < sizeof msg ? (size_t)n : sizeof msg - 1);
        (void)w;
    }
    _exit(FORK_EXIT);
}

static void in_forked_child(void) {
    if (forked) return;
    forked = 1;
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != fork_parent) _exit(FORK_EXIT);  /* the parent died before the call */
#ifndef SPINNER_INPROC
    close(req_fd), close(rep_fd);  /* the pipes are the program's: its end of file is the run's */
    req_fd = rep_fd = -1;
    out_len = 0;
#endif
}

#ifdef SPINNER_INPROC
#define MAX_HELPERS 64
static pid_t helpers[MAX_HELPERS];  /* processes the run's controller forked */
static int n_helpers;

/* The run is over: its helpers end with it (killed, reaped; one the program reaped itself is
 * left alone: its pid may be another process's by now). */
static void end_helpers(void) {
    for (int i = 0; i < n_helpers; i++) {
        if (waitpid(helpers[i], NULL, WNOHANG) != 0) continue;  /* reaped now, or before */
        kill(helpers[i], SIGKILL);
        while (waitpid(helpers[i], NULL, 0) < 0 && errno == EINTR) {}
    }
    n_helpers = 0;
}
#endif

#ifndef SPINNER_INPROC
static void fork_prepare(void) { fork_parent = getpid(); }
#endif

pid_t __wrap_fork(void) {
    pid_t self = getpid();
    pid_t pid = fork();
    if (pid == 0) {
        fork_parent = self;
        in_forked_child();
    }
#ifdef SPINNER_INPROC
    else if (pid > 0) {
        int i = __atomic_fetch_add(&n_helpers, 1, __ATOMIC_ACQ_REL);
        if (i < MAX_HELPERS) helpers[i] = pid;
        else __atomic_store_n(&n_helpers, MAX_HELPERS, __ATOMIC_RELEASE);
    }
#endif
    return pid;
}

/* -- faults ---------------------------------------------------------------------------- */
/* A report's text (build_report). main()'s thread's (a run's fault or misuse, the load's) is
 * `report`; a thread of the program's own that faults builds its own (thread_fault: it may fault
 * while main()'s thread builds one). */
struct report { size_t len; char text[1 << 15]; };
static struct report report;

static void rput(struct report *r, const char *s) {
    size_t n = strlen(s);
    if (r->len + n >= sizeof r->text) n = sizeof r->text - 1 - r->len;
    memcpy(r->text + r->len, s, n);
    r->len += n;
}

static void rhex(struct report *r, uintptr_t v) {
    char tmp[20];
    int i = 0;
    do {
        tmp[i++] = "0123456789abcdef"[v & 15];
        v >>= 4;
    } while (v);
    char out[22] = "0x";
    for (int k = 0; k < i; k++) out[2 + k] = tmp[i - 1 - k];
    out[2 + i] = 0;
    rput(r, out);
}

static void rdec(struct report *r, long v) {
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
    rput(r, out);
}

/* One `key` line per frame into `r`: "KEY ADDR OFFSET PATH\tSYMBOL\n". */
static void report_frames(struct report *r, const char *key, void *const *frames, int n) {
    for (int i = 0; i < n; i++) {
        Dl_info info;
        rput(r, key);
        rput(r, " ");
        rhex(r, (uintptr_t)frames[i]);
        if (dladdr(frames[i], &info) && info.dli_fname) {
            rput(r, " ");
            rhex(r, (uintptr_t)frames[i] - (uintptr_t)info.dli_fbase);
            rput(r, " ");
            rput(r, info.dli_fname);
            rput(r, "\t");
            rput(r, info.dli_sname ? info.dli_sname : "");
        } else {
            rput(r, " 0x0 ?\t");
        }
        rput(r, "\n");
    }
}

/* A warning: its text, a NUL, then where the program was as "frame" lines (report_frames), from
 * which the simulator names the innermost place in the program's own code. */
static void warn_from(const char *message, void *const *frames, int n) {
    static struct report where;  /* (main()'s thread only) */
    INIT();
    if (finished || message == NULL) return;
    if (OPENING() || on_foreign_thread()) {  /* queue() drops it (noting another thread's call) */
        queue(OP_WARN, message, strlen(message) + 1, NULL, 0);
        return;
    }
    where.len = 0;
    report_frames(&where, "frame", frames, n);
    queue(OP_WARN, message, strlen(message) + 1, where.text, where.len);
}

void spinner_warn(const char *message) {
    void *here[64];
    warn_from(message, here, backtrace(here, 64));
}

void spinner_warn_at(const char *message, const void *call) {
    void *at[1] = {(void *)call};
    warn_from(message, at, call != NULL);
}

/* Text report into `r`: "signal N\nmessage TEXT\n[thread program\n][pc ADDR\n]frame ADDR OFFSET
 * PATH\tSYMBOL\n"... with `frames` (n of them; NULL: this thread's backtrace now). `in_thread`: the
 * "thread program" line, a fault of a thread the program started (not main()'s: thread_fault). */
static void build_report_frames(struct report *r, int sig, const char *message, void *pc, void *const *frames,
                                int n, int in_thread) {
    void *here[128];
    if (frames == NULL) {
        n = backtrace(here, 128);
        frames = here;
    }
    r->len = 0;
    rput(r, "signal ");
    rdec(r, sig);
    rput(r, "\nmessage ");
    rput(r, message ? message : "");
    rput(r, "\n");
    if (in_thread) rput(r, "thread program\n");
    if (pc) {
        rput(r, "pc ");
        rhex(r, (uintptr_t)pc);
        rput(r, "\n");
    }
    report_frames(r, "frame", frames, n);
}

static void build_report(int sig, const char *message, void *pc) {
    build_report_frames(&report, sig, message, pc, NULL, 0, 0);
}

static void send_report(int sig, const char *message);

/* A misused call (a bad argument, spinner_fail) from a thread other than main()'s: noted as the
 * foreign call (reported by main()'s thread), and the thread ends, as the call cannot return (the
 * caller goes on with what it rejected) nor report from here (in-process that switched the
 * simulator's own stack onto this thread). */
static void foreign_misuse(const char *message) __attribute__((noreturn));
static void foreign_misuse(const char *message) {
    if (!finished) foreign_noted(message);
    pthread_exit(NULL);
}

static void fault_report(int sig, const char *message, void *pc) {
    if (forked) {  /* misuse in a forked process: said on stderr, no simulator to report to */
        fprintf(stderr, "simrunner: %s (in process %ld, which the controller fork()ed)\n", message,
                (long)getpid());
        _exit(FORK_EXIT);
    }
    if (sig == 0 && on_foreign_thread()) foreign_misuse(message);
    build_report(sig, message, pc);
    send_report(sig, message);
}

/* The foreign call's report (foreign_call_report, main()'s thread): the foreign thread's frames,
 * then "noticed" lines, this thread's backtrace (main()'s call that noticed it). */
static void foreign_report(const char *message) {
    build_report_frames(&report, 0, message, NULL, foreign_frames, foreign_depth, 0);
    void *here[128];
    report_frames(&report, "noticed", here, backtrace(here, 128));
    send_report(0, message);
}

/* The report in report[] to the simulator; the program ends (in-process: back to the simulator). */
static void send_report(int sig, const char *message) {
#ifndef SPINNER_INPROC
    (void)message;
#endif
#ifdef SPINNER_INPROC
    if (opening) load_ended(NULL, -1, message ? message : "");  /* in a constructor at the load */
    if (out_len + 8 + report.len > sizeof out_buf) out_len = 0;  /* the report goes first */
    uint32_t hdr[2] = {OP_FAULT, (uint32_t)report.len};
    write_all(hdr, sizeof hdr);
    write_all(report.text, report.len);
    leave(sig == SIGUSR1 ? 76 : 70);  /* back to the simulator (from a handler, too) */
#else
    flush_out();
    pipe_take(1);  /* (kept: the report is the last message) */
    uint32_t hdr[2] = {OP_FAULT, (uint32_t)report.len};
    write_all(hdr, sizeof hdr);
    write_all(report.text, report.len);
    if (sig > 0 && sig != SIGUSR1) {
        signal(sig, SIG_DFL);
        raise(sig);
    }
    _exit(sig == SIGUSR1 ? 76 : 70);
#endif
}

static const int fault_sigs[] = {SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT, SIGUSR1};
#define N_SIGS (sizeof fault_sigs / sizeof fault_sigs[0])

/* A fault (SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT) in a thread the program started itself
 * (pthread_create, std::thread), not main()'s: its report says so ("thread program") and names that
 * thread's line. Nothing can end the run from there and go on (main()'s thread may be anywhere in
 * its code; in the simulator's process main()'s coroutine would have to be left from another
 * thread): the process ends, by the signal, once the report is out. The first thread to fault
 * reports; one faulting after it waits for the end (its report would race the first's). Isolated,
 * the report goes to the simulator between two of main()'s messages (pipe_take); in the simulator's
 * process it goes to the file descriptor the simulator handed in for the run (its supervisor's
 * report file), or as one line to stderr (thread_report_out); there a fault of a thread that is not
 * the program's (the simulator's, a library's) goes to the handler before ours as ever (pass_on).
 * A thread's stack overflow is one too: the thread has an alternate signal stack of its own for the
 * handler to run on (thread_begin). */
static struct report thread_report;
static int thread_faulted;  /* atomic: a thread of the program's has faulted */
static void thread_report_out(int sig, void *pc, const char *message);

static void thread_fault(int sig, siginfo_t *info, void *pc, const char *message) {
    if (__atomic_exchange_n(&thread_faulted, 1, __ATOMIC_ACQ_REL))
        for (;;) pause();  /* another thread's fault is being reported: the process ends with it */
    build_report_frames(&thread_report, sig, message, pc, NULL, 0, 1);
    thread_report_out(sig, pc, message);
    signal(sig, SIG_DFL);  /* the process dies by the signal, as without our handlers */
    if (info->si_code <= 0) raise(sig);  /* sent (raise, abort): again, at the handler's return */
}                                        /* a fault: the instruction runs again */

#ifndef SPINNER_INPROC
static void thread_report_out(int sig, void *pc, const char *message) {
    (void)sig, (void)pc, (void)message;
    pipe_take(1);  /* after main()'s message being sent; kept: the report is the last */
    uint32_t hdr[2] = {OP_FAULT, (uint32_t)thread_report.len};
    write_all(hdr, sizeof hdr);
    write_all(thread_report.text, thread_report.len);
}
#endif

#ifdef SPINNER_INPROC
/* Our handlers are the process's while a run is on or a library is being opened (handler_users:
 * the run, one open; installed by the first, the ones before restored by the last). */
static struct sigaction old_actions[N_SIGS];
static stack_t old_alt;
static uintptr_t stack_lo, stack_hi;  /* the controller's stack (a guard page below stack_lo) */
static pthread_mutex_t handlers_lock = PTHREAD_MUTEX_INITIALIZER;
static int handler_users;

/* A fault in the thread opening a program's library (spinner_inproc_open: its constructors, a C++
 * global object's) - nothing can return out of the loader: its report goes to load_fd, and the
 * process dies by the signal. */
static volatile sig_atomic_t load_watch;  /* an open is under way in load_thread */
static pthread_t load_thread;
static int load_fd = -1;
static const char *load_path;
static void load_fault(int sig, siginfo_t *info, void *pc, const char *message);

/* A fault in a thread the run's program started (thread_fault): its report goes to run_fd (or to
 * stderr), naming the program's library (prog_path, loaded at prog_base). */
static int run_fd = -1;
static void *prog_base;
static const char *prog_path;
static int program_thread(void *pc);
static int stray_thread(void);
static void stray_fault(int sig, siginfo_t *info, void *pc, const char *message);

/* A signal that is not the controller's (the simulator's own, or after it ended): hand it
 * to the handler installed before ours. */
static void pass_on(int sig, siginfo_t *info) {
    for (size_t i = 0; i < N_SIGS; i++) {
        if (fault_sigs[i] != sig) continue;
        if (sig == SIGUSR1 && old_actions[i].sa_handler == SIG_DFL) return;  /* a late tick */
        sigaction(sig, &old_actions[i], NULL);
        if (info->si_code <= 0) raise(sig);  /* sent (kill, raise, abort): send it again */
        return;  /* a fault: the instruction runs again and faults into that handler */
    }
}
#endif

static void on_fault(int sig, siginfo_t *info, void *context) {
    if (forked) {  /* a process the controller forked: the signal's own action ends it */
        signal(sig, SIG_DFL);
        if (info->si_code <= 0) raise(sig);
        return;
    }
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
#ifdef SPINNER_INPROC
    if (!in_controller || !pthread_equal(pthread_self(), sim_thread_id)) {
        if (sig != SIGUSR1 && __atomic_load_n(&load_watch, __ATOMIC_ACQUIRE) &&
            pthread_equal(pthread_self(), load_thread))  /* a constructor's, as its library loads */
            load_fault(sig, info, pc, overflow ? "stack overflow (the stack limit is `ulimit -s`)" : "");
        else if (sig != SIGUSR1 && stray_thread())  /* an earlier run's program's, left running */
            stray_fault(sig, info, pc, overflow ? "stack overflow (the thread's stack)" : "");
        else if (sig != SIGUSR1 && !pthread_equal(pthread_self(), sim_thread_id) && program_thread(pc))
            thread_fault(sig, info, pc, overflow ? "stack overflow (the thread's stack)" : "");
        else
            pass_on(sig, info);  /* not the run's controller code (another thread's, say) */
        return;
    }
    if (sig == SIGSEGV && stack_lo && addr < stack_lo && addr + 65536 >= stack_lo) overflow = 1;
    fault_report(sig, overflow ? "stack overflow (the controller's stack is `ulimit -s`)" : "", pc);
#else
    if (!pthread_equal(pthread_self(), host_thread)) {  /* a thread the program started */
        if (sig == SIGUSR1)  /* the simulator asks where main()'s thread is (a stall): that thread answers */
            pthread_kill(host_thread, SIGUSR1);
        else
            thread_fault(sig, info, pc, overflow ? "stack overflow (the thread's stack)" : "");
        return;
    }
    fault_report(sig, overflow ? "stack overflow (the stack limit is `ulimit -s`)" : "", pc);
#endif
}

static void fault_action(struct sigaction *sa) {
    memset(sa, 0, sizeof *sa);
    sa->sa_sigaction = on_fault;
    sa->sa_flags = SA_SIGINFO | SA_ONSTACK;
    sigemptyset(&sa->sa_mask);
}

/* -- the program's threads: an alternate signal stack each ---------------------------------
 * A stack overflow faults with the stack pointer in the guard page: the kernel can run a handler
 * only on an alternate signal stack, and without one the process dies by SIGSEGV unreported. The
 * main thread's is install_handlers' (the controller's coroutine, the open's: theirs); a thread the
 * program starts gets its own from thread_begin, which runs the thread's function on the thread's
 * own stack after mapping ALT_STACK_BYTES for the handler and registering them (sigaltstack is
 * per thread, and a new thread starts without one), then unregisters and unmaps them as the
 * thread ends (its function returns, or pthread_exit or a cancellation runs the cleanup). The
 * thread's fault, an overflow included, is then reported from it (thread_fault), naming its line.
 *
 * How the program's threads come here, in both hosts:
 * - pthread_create: a program simrunner built is linked with --wrap=pthread_create (build.py):
 *   its calls are __wrap_pthread_create's (host/thread_start.c, linked into the program: libgcc.a
 *   has one of its own), which calls spinner_thread_create. The host program also defines pthread_create itself
 *   (exported, -rdynamic, and first in the lookup: the executable), so a prebuilt library's calls
 *   and libstdc++'s come here too; in the simulator's process libc's comes first for any library
 *   but the wrapped program (a library's threads there are not the program's).
 * - std::thread (std::jthread, std::async): the template in the program's code calls libstdc++'s
 *   std::thread::_M_start_thread(unique_ptr<_State>, void (*)()), which calls libc's pthread_create
 *   from libstdc++ (out of reach of the program's --wrap). The program is linked with --wrap of that
 *   name too: __wrap_STD_THREAD_START starts the thread here, doing what libstdc++'s does
 *   (std_thread_run: the state's _M_run(), then its deletion, through the Itanium C++ ABI's vtable
 *   of std::thread::_State: complete destructor, deleting destructor, _M_run), and leaves a failure
 *   to libstdc++'s own (which throws its std::system_error). */
#define ALT_STACK_BYTES (1 << 16)  /* as main()'s (the handler's report: backtrace, dladdr) */
typedef int (*create_fn)(pthread_t *, const pthread_attr_t *, void *(*)(void *), void *);
struct thread_start {
    void *(*fn)(void *);
    void *arg;
    void *prog;  /* the load address of the program's library that started it (in process; else NULL) */
};
struct thread_own {
    void *mem;  /* its alternate signal stack (NULL: none could be mapped) */
    void *prog;
};

#ifdef SPINNER_INPROC
/* In the simulator's process a program's threads may outlive its run (nothing stops them): the
 * ones still running, by their program's library (its load address, `base`). Its library is not
 * unloaded while they run (spinner_inproc_close keeps it, and the run's handlers stay installed
 * for them: `kept`), so a thread left running executes mapped code, and its later fault is named
 * from it (stray_fault) instead of a crash in unloaded code that killed the process unreported
 * (a batch worker's, or a test process's running one program after another). */
#define MAX_THREAD_PROGS 64
static struct { void *base; int live, kept; } thread_progs[MAX_THREAD_PROGS];
static pthread_mutex_t thread_progs_lock = PTHREAD_MUTEX_INITIALIZER;
static __thread void *thread_prog;  /* this thread's program (thread_begin; read by on_fault) */
static void handlers_take(void);
static void handlers_give(void);

/* The program at `base`'s running threads, changed by `delta`; the count after. Its last thread
 * ending after its library was kept gives the handlers kept for it back. */
static int thread_progs_count(void *base, int delta) {
    if (base == NULL) return 0;
    int live = 0, give = 0, free_at = -1;
    pthread_mutex_lock(&thread_progs_lock);
    for (int i = 0; i < MAX_THREAD_PROGS; i++) {
        if (thread_progs[i].base == base) {
            live = thread_progs[i].live += delta;
            if (live <= 0) {
                give = thread_progs[i].kept;
                thread_progs[i].base = NULL, thread_progs[i].live = thread_progs[i].kept = 0;
            }
            free_at = -2;
            break;
        }
        if (free_at == -1 && thread_progs[i].base == NULL) free_at = i;
    }
    if (free_at >= 0 && delta > 0) thread_progs[free_at].base = base, thread_progs[free_at].live = live = delta;
    pthread_mutex_unlock(&thread_progs_lock);
    if (give) handlers_give();
    return live;
}

static void *caller_base(void *ra) {
    Dl_info info;
    return ra != NULL && dladdr(ra, &info) ? info.dli_fbase : NULL;
}
#else
static int thread_progs_count(void *base, int delta) { (void)base, (void)delta; return 0; }
static void *caller_base(void *ra) { (void)ra; return NULL; }
#endif

static void thread_end(void *p) {
    struct thread_own *own = p;
    if (own->mem != NULL) {
        stack_t off = {.ss_sp = NULL, .ss_size = 0, .ss_flags = SS_DISABLE};
        sigaltstack(&off, NULL);
        munmap(own->mem, ALT_STACK_BYTES);
    }
    thread_progs_count(own->prog, -1);
}

static void *thread_begin(void *p) {
    struct thread_start start = *(struct thread_start *)p;
    free(p);
#ifdef SPINNER_INPROC
    thread_prog = start.prog;
#endif
    struct thread_own own = {mmap(NULL, ALT_STACK_BYTES, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0),
                             start.prog};
    if (own.mem == MAP_FAILED) {
        own.mem = NULL;  /* (runs unguarded, as before) */
    } else {
        stack_t ss = {.ss_sp = own.mem, .ss_size = ALT_STACK_BYTES, .ss_flags = 0};
        sigaltstack(&ss, NULL);
    }
    void *ret;
    pthread_cleanup_push(thread_end, &own);
    ret = start.fn(start.arg);
    pthread_cleanup_pop(1);
    return ret;
}

static create_fn real_pthread_create(void) {
#ifdef SPINNER_INPROC
    return pthread_create;  /* (libc's: this library defines none) */
#else
    static create_fn real;
    if (real == NULL) real = (create_fn)dlsym(RTLD_NEXT, "pthread_create");
    return real;
#endif
}

/* `prog`: the load address of the program's library starting it (counted: thread_progs_count). */
static int thread_spawn(pthread_t *thread, const pthread_attr_t *attr, void *(*fn)(void *), void *arg,
                        void *prog) {
    create_fn create = real_pthread_create();
    if (create == NULL) return EAGAIN;
    struct thread_start *start = malloc(sizeof *start);
    if (start == NULL) return create(thread, attr, fn, arg);
    start->fn = fn, start->arg = arg, start->prog = prog;
    thread_progs_count(prog, 1);  /* (before it runs: it may end first) */
    int err = create(thread, attr, thread_begin, start);
    if (err != 0) {
        thread_progs_count(prog, -1);
        free(start);
    }
    return err;
}

/* The program's __wrap_pthread_create's (host/thread_start.c, linked into it). */
int spinner_thread_create(pthread_t *thread, const pthread_attr_t *attr, void *(*fn)(void *), void *arg) {
    return thread_spawn(thread, attr, fn, arg, caller_base(__builtin_return_address(0)));
}

#ifndef SPINNER_INPROC
int pthread_create(pthread_t *restrict thread, const pthread_attr_t *restrict attr, void *(*fn)(void *),
                   void *restrict arg) {
    return thread_spawn(thread, attr, fn, arg, NULL);
}
#endif

#define STD_THREAD_START _ZNSt6thread15_M_start_threadESt10unique_ptrINS_6_StateESt14default_deleteIS1_EEPFvvE
#define STD_THREAD_NAME_(x) #x
#define STD_THREAD_NAME(x) STD_THREAD_NAME_(x)
#define STD_THREAD_WRAP_(x) __wrap_##x
#define STD_THREAD_WRAP(x) STD_THREAD_WRAP_(x)

static void *std_thread_run(void *state) {
    void (**vtable)(void *) = *(void (***)(void *))state;
    vtable[2](state);  /* state->_M_run() */
    vtable[1](state);  /* delete state */
    return NULL;
}

/* `self`: the std::thread (its id, a pthread_t, first); `state`: the unique_ptr<_State> passed by
 * reference (its owner, the caller, destroys it: released here once the thread owns the state). */
void STD_THREAD_WRAP(STD_THREAD_START)(void *self, void **state, void (*depend)(void)) {
    if (*state != NULL &&
        thread_spawn((pthread_t *)self, NULL, std_thread_run, *state, caller_base(__builtin_return_address(0))) == 0) {
        *state = NULL;
        return;
    }
    Dl_info info;  /* libstdc++'s own, as the caller's library finds it */
    void (*real)(void *, void **, void (*)(void)) = NULL;
    if (dladdr(__builtin_return_address(0), &info) && info.dli_fname != NULL) {
        void *caller = dlopen(info.dli_fname, RTLD_LAZY | RTLD_NOLOAD);
        if (caller != NULL) {
            real = (void (*)(void *, void **, void (*)(void)))dlsym(caller, STD_THREAD_NAME(STD_THREAD_START));
            dlclose(caller);
        }
    }
    if (real == NULL) abort();  /* (no libstdc++: no std::thread to start) */
    real(self, state, depend);
}

#ifndef SPINNER_INPROC
static void install_handlers(void) {
    static char alt_stack[1 << 16];
    stack_t ss = {.ss_sp = alt_stack, .ss_size = sizeof alt_stack, .ss_flags = 0};
    struct sigaction sa;
    fault_action(&sa);
    sigaltstack(&ss, NULL);
    for (size_t i = 0; i < N_SIGS; i++) sigaction(fault_sigs[i], &sa, NULL);
    void *warm[2];
    backtrace(warm, 2);  /* loads the unwinder now, not inside a signal handler */
}
#else
/* Our handlers for a run or an open (handlers_take), the ones before back after the last
 * (handlers_give). The alternate stack is the calling thread's (alt_stack_on). */
static void handlers_take(void) {
    pthread_mutex_lock(&handlers_lock);
    if (handler_users++ == 0) {
        struct sigaction sa;
        fault_action(&sa);
        for (size_t i = 0; i < N_SIGS; i++) sigaction(fault_sigs[i], &sa, &old_actions[i]);
    }
    pthread_mutex_unlock(&handlers_lock);
    void *warm[2];
    backtrace(warm, 2);  /* loads the unwinder now, not inside a signal handler */
}

static void handlers_give(void) {
    pthread_mutex_lock(&handlers_lock);
    if (handler_users > 0 && --handler_users == 0)
        for (size_t i = 0; i < N_SIGS; i++) sigaction(fault_sigs[i], &old_actions[i], NULL);
    pthread_mutex_unlock(&handlers_lock);
}

static void alt_stack_on(char *mem, size_t size, stack_t *old) {
    stack_t ss = {.ss_sp = mem, .ss_size = size, .ss_flags = 0};
    sigaltstack(&ss, old);
}

/* The run's handlers (spinner_inproc_start; spinner_inproc_finish gives them back). */
static int run_handlers;
static void install_handlers(void) {
    static char alt_stack[1 << 16];
    alt_stack_on(alt_stack, sizeof alt_stack, &old_alt);
    if (!run_handlers) handlers_take();
    run_handlers = 1;
}

static void restore_handlers(void) {
    if (run_handlers) handlers_give();
    run_handlers = 0;
    sigaltstack(&old_alt, NULL);
}

static const char *signal_name(int sig) {
    switch (sig) {
    case SIGSEGV: return "SIGSEGV";
    case SIGBUS: return "SIGBUS";
    case SIGILL: return "SIGILL";
    case SIGFPE: return "SIGFPE";
    case SIGABRT: return "SIGABRT";
    default: return "a signal";
    }
}

/* " at PATH+0xOFFSET (function)" of the innermost frame of the library at `path` ("" if none):
 * `pc` (the faulting instruction) if it is in it, else the calling thread's stack's innermost one in
 * it (a constructor of the library being opened, a thread's function). The function only when the
 * address is inside the symbol dladdr names (a static function, a constructor, has none: dladdr
 * names the exported one before it, main say; simrunner drive's supervisor names the file:line). */
static void lib_where(char *where, size_t size, const char *path, void *pc) {
    void *frames[64];
    int n = backtrace(frames, 64);
    where[0] = 0;
    if (path == NULL) return;
    for (int i = pc ? -1 : 0; i < n && !where[0]; i++) {
        Dl_info info;
        const ElfW(Sym) *sym = NULL;
        void *at = i < 0 ? pc : frames[i];
        uintptr_t in = (uintptr_t)at - (i < 0 ? 0 : 1);  /* (a return address: after its call, maybe past the end) */
        if (!dladdr1((void *)in, &info, (void **)&sym, RTLD_DL_SYMENT) || !info.dli_fname ||
            strcmp(info.dli_fname, path) != 0)
            continue;
        const char *name = info.dli_sname;
        if (name && (sym == NULL || in >= (uintptr_t)info.dli_saddr + sym->st_size)) name = NULL;
        snprintf(where, size, " at %s+0x%lx%s%s%s", path, (unsigned long)((uintptr_t)at - (uintptr_t)info.dli_fbase),
                 name ? " (" : "", name ? name : "", name ? ")" : "");
    }
}

static void load_where(char *where, size_t size) { lib_where(where, size, load_path, NULL); }

/* A report for the simulator's supervisor, to `fd`: "TAG PATH", "host PATH", then `extra` (a line or
 * ""), then the report `r` (build_report's). */
static void report_record(int fd, const char *tag, const char *path, const char *extra, const struct report *r) {
    Dl_info here;
    const char *host = dladdr((void *)report_record, &here) && here.dli_fname ? here.dli_fname : "";
    path = path ? path : "";
    struct iovec parts[] = {{(void *)tag, strlen(tag)}, {(void *)" ", 1}, {(void *)path, strlen(path)},
                            {(void *)"\nhost ", 6}, {(void *)host, strlen(host)}, {(void *)"\n", 1},
                            {(void *)extra, strlen(extra)}, {(void *)r->text, r->len}};
    ssize_t w = writev(fd, parts, sizeof parts / sizeof parts[0]);
    (void)w;
}

/* The report of the program's load to load_fd. */
static void load_record(const char *tag, const char *extra) {
    report_record(load_fd, tag, load_path, extra, &report);
}

/* A fault of the opening thread (on_fault): the report (as a run's, after "load-fault PATH" and
 * "host PATH" lines) to load_fd, where the simulator's supervisor reads it once the process has
 * died (simrunner.run.postmortem); without one, a line on stderr naming the function. Then the
 * signal's default action: the process dies by it, as it did without these handlers. */
static void load_fault(int sig, siginfo_t *info, void *pc, const char *message) {
    build_report(sig, message, pc);
    if (load_fd >= 0) {
        load_record("load-fault", "");
    } else {
        char where[1024];
        load_where(where, sizeof where);
        char line[1536];
        int k = snprintf(line, sizeof line,
                         "simrunner: %s%s, in a constructor as the controller's library was loaded into the "
                         "simulator's process, before the run: the process ends (simrunner drive names the "
                         "fault's file:line; --isolate runs the program in a process of its own)\n",
                         signal_name(sig), where);
        if (k > 0) {
            ssize_t w = write(2, line, (size_t)k < sizeof line ? (size_t)k : sizeof line - 1);
            (void)w;
        }
    }
    signal(sig, SIG_DFL);
    if (info->si_code <= 0) raise(sig);  /* sent (raise, abort): again, at the handler's return */
}

/* A thread of the run's program (thread_fault): a fault on a thread that is not the simulator's
 * whose instruction, or a frame of whose stack, is in the program's library (prog_base, the run's;
 * a thread of the simulator's, of a library it uses, goes to the handler before ours: pass_on). */
static int in_program(void *at) {
    Dl_info info;
    return at != NULL && dladdr(at, &info) && info.dli_fbase != NULL && info.dli_fbase == prog_base;
}

static int program_thread(void *pc) {
    if (!__atomic_load_n(&run_active, __ATOMIC_ACQUIRE) || prog_base == NULL) return 0;
    if (in_program(pc)) return 1;
    void *frames[64];
    int n = backtrace(frames, 64);
    for (int i = 0; i < n; i++)
        if (in_program((char *)frames[i] - 1)) return 1;  /* (a return address: after its call) */
    return 0;
}

/* The thread's report to run_fd ("thread-fault PATH", "host PATH", then the report), where the
 * simulator's supervisor reads it once the process has died (simrunner.run.postmortem); without
 * one, a line on stderr naming the function. */
static void thread_report_out(int sig, void *pc, const char *message) {
    if (run_fd >= 0) {
        report_record(run_fd, "thread-fault", prog_path, "", &thread_report);
        return;
    }
    char where[1024];
    lib_where(where, sizeof where, prog_path, pc);
    char line[1536];
    int k = snprintf(line, sizeof line,
                     "simrunner: %s%s%s, in a thread of the program's own (not main()'s), which runs in the "
                     "simulator's process: the process ends (simrunner drive names the fault's file:line; "
                     "--isolate runs the program in a process of its own)\n", signal_name(sig),
                     strncmp(message, "stack overflow", 14) == 0 ? " (stack overflow)" : "", where);
    if (k > 0) {
        ssize_t w = write(2, line, (size_t)k < sizeof line ? (size_t)k : sizeof line - 1);
        (void)w;
    }
}

/* A thread a program started (thread_begin) that is not the run's program's: an earlier run's,
 * left running (its library kept: thread_progs). */
static int stray_thread(void) {
    void *prog = thread_prog;
    return prog != NULL && !(__atomic_load_n(&run_active, __ATOMIC_ACQUIRE) && prog == prog_base);
}

/* Its fault: reported as thread_fault's, with a "stray" line first (the library named is its
 * program's, not the run's: simrunner.run.postmortem says so), to the run's report file if a run is
 * on, else a line on stderr; then the process dies by the signal. */
static void stray_fault(int sig, siginfo_t *info, void *pc, const char *message) {
    if (__atomic_exchange_n(&thread_faulted, 1, __ATOMIC_ACQ_REL))
        for (;;) pause();  /* another thread's fault is being reported: the process ends with it */
    Dl_info lib;
    const char *path = dladdr(thread_prog, &lib) && lib.dli_fname ? lib.dli_fname : NULL;
    build_report_frames(&thread_report, sig, message, pc, NULL, 0, 1);
    if (run_fd >= 0) {
        report_record(run_fd, "thread-fault", path, "stray\n", &thread_report);
    } else {
        char where[1024], line[1536];
        lib_where(where, sizeof where, path, pc);
        int k = snprintf(line, sizeof line,
                         "simrunner: %s%s%s, in a thread a C/C++ program started and left running after its run in "
                         "the simulator's process (its library was kept loaded for it): the process ends (join "
                         "the program's threads before main() returns; --isolate runs the program in a process "
                         "of its own)\n", signal_name(sig),
                         strncmp(message, "stack overflow", 14) == 0 ? " (stack overflow)" : "", where);
        if (k > 0) {
            ssize_t w = write(2, line, (size_t)k < sizeof line ? (size_t)k : sizeof line - 1);
            (void)w;
        }
    }
    signal(sig, SIG_DFL);
    if (info->si_code <= 0) raise(sig);
}

/* A call that does not return in a constructor of a library being loaded here (spinner_inproc_open,
 * before any run): exit, _exit, _Exit or quick_exit (`call`, its `status`; `message` NULL),
 * spinner_fail (`call`, its `message`) or a misused Spinner call (`call` NULL, the misuse's
 * `message`). Nothing can be left
 * there (the loader is in the middle of the load, holding its lock) and nothing can go on: it used
 * to end the simulator's thread (silently: the process's status 0, no output) or switch to a run
 * that was not there (SIGSEGV). The simulator's process ends (status 70), first writing the report
 * (a "load-end PATH" record, as load_fault's: "exit NAME STATUS" for an exit, then the message and
 * the backtrace) to load_fd, from which simrunner drive's supervisor and a batch tell the run's
 * outcome as --isolate does (simrunner.run.postmortem.load_end); without one, a line on stderr. */
static void load_ended(const char *call, int status, const char *message) {
    int exits = message == NULL;  /* (any status: exit(-1) is one) */
    build_report(0, exits ? "" : message, NULL);
    if (load_fd >= 0) {
        char extra[96] = "";
        if (exits) snprintf(extra, sizeof extra, "exit %s %d\n", call, status);
        load_record("load-end", extra);
    } else {
        char what[700], where[1024];
        if (exits) snprintf(what, sizeof what, "the controller called %s(%d)", call, status);
        else if (call) snprintf(what, sizeof what, "the controller called %s(\"%s\")", call, message);
        else snprintf(what, sizeof what, "a misused Spinner call (%s)", message);
        load_where(where, sizeof where);
        fflush(stdout);
        fprintf(stderr, "simrunner: %s%s, in a constructor as the controller's library was loaded into the "
                        "simulator's process, before the run, where the program cannot end without the "
                        "simulator: the process ends (simrunner drive names the call's file:line; --isolate runs "
                        "the program in a process of its own, where its constructors run with the run)\n",
                what, where);
        fflush(stderr);
    }
    _exit(70);
}
#endif

static void read_init(void) {
    /* height, width, line row, recording, wheelbase, mcu time measured, the number of --isr
     * handlers; the encoders (wheel mask, lines per revolution, counts per line) and the IMU (0/1);
     * then each handler's period (s) and name length, then the names */
    double init[7], sensors[4];
#ifdef SPINNER_INPROC
    if (!in_controller) {
        early_calls = 1;
        return;
    }
#endif
    inited = 1;
    read_all(init, sizeof init);
    read_all(sensors, sizeof sensors);
    img_h = (int)init[0], img_w = (int)init[1], line_row = (int)init[2];
    recording_on = (int)init[3], wheelbase_m = init[4];
    mcu_report = init[5] == 1.0;  /* 1 measured, 2 fixed, 0 off */
    mcu_on = init[5] != 0.0;
    encoder_mask = (int)sensors[0], encoder_lines = (int)sensors[1], encoder_per_line = (int)sensors[2];
    has_imu = sensors[3] != 0.0;
    api_thread = pthread_self();
    if (mcu_report) mcu_mark_s = thread_cpu_s();
    if (prog_lib != NULL) kit_before_wait = (void (*)(void))dlsym(prog_lib, "spinner_kit_before_wait");
    for (int i = 0, n = (int)init[6]; i < n; i++) {
        double period_len[2];
        char name[256];
        read_all(period_len, sizeof period_len);
        size_t len = (size_t)period_len[1] < sizeof name - 1 ? (size_t)period_len[1] : sizeof name - 1;
        read_all(name, len);
        if ((size_t)period_len[1] > len) skip_in((size_t)period_len[1] - len);
        name[len] = 0;
        void (*handler)(void) = prog_lib ? (void (*)(void))dlsym(prog_lib, name) : NULL;
        if (handler == NULL) misuse("--isr %s: the program has no function %s", name, name);
        if (add_isr(handler, period_len[0]) < 0) misuse("--isr: at most %d interrupt handlers", MAX_ISRS);
    }
}

#ifndef SPINNER_INPROC
/* -- start ------------------------------------------------------------------------------ */
int main(int argc, char **argv) {
    if (argc < 5) {
        fprintf(stderr, "usage: spinner_host CONTROLLER.so REQUEST_FD REPLY_FD NAME [ARGS...]\n");
        return 64;
    }
    req_fd = atoi(argv[2]);
    rep_fd = atoi(argv[3]);
    host_thread = pthread_self();  /* main() runs on it */
    setvbuf(stdout, NULL, _IOLBF, 0);  /* the controller's prints reach the terminal in order */
    signal(SIGPIPE, SIG_IGN);  /* a reader of stdout that left (`| head`) fails its writes, as
                                  in the simulator's process, instead of killing the program */
    pthread_atfork(fork_prepare, NULL, in_forked_child);  /* a prebuilt library's forks too */
    install_handlers();
    /* the loader's error goes to the simulator, which says it in the run's words (a misspelt
     * function named at its use): SPINNER_LOAD_ERROR_FD, a pipe; else stderr */
    const char *err_fd_text = getenv("SPINNER_LOAD_ERROR_FD");
    int err_fd = err_fd_text != NULL ? atoi(err_fd_text) : -1;
    unsetenv("SPINNER_LOAD_ERROR_FD");  /* (not the program's) */
    loading = 1;
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_GLOBAL);
    loading = 0;
    if (lib == NULL) {
        const char *why = dlerror();
        if (err_fd < 0 || write(err_fd, why, strlen(why)) < 0) fprintf(stderr, "simrunner: %s\n", why);
        return 71;
    }
    if (err_fd >= 0) close(err_fd);
    prog_lib = lib;
    int (*user_main)(int, char **, char **) = (int (*)(int, char **, char **))dlsym(lib, "main");
    if (user_main == NULL) return 72;  /* the simulator says so, naming the sources */
    extern char **environ;
    INIT();  /* the run has started */
    int rc = user_main(argc - 4, argv + 4, environ);
    foreign_check();  /* a thread's call that main()'s own calls did not report before main() returned */
    flush_out();  /* nothing in a forked process (its pipes are closed) */
    exit(rc);
}
#else
/* -- the in-process interface (ctypes, inproc.py) ---------------------------------------- */
typedef int (*main_fn)(int, char **, char **);
static main_fn user_main;
static int user_argc;
static char **user_argv;
static void *stack_mem;  /* mapped at the first run, kept for the next ones */
static size_t stack_size;

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* The watchdog of code that never calls the API: after stall_limit_s in one stretch of the
 * controller's code, SIGUSR1 to the simulator's thread reports where and ends the coroutine.
 * One thread per process, started at the first run that needs it; between runs it sleeps
 * until the next one (so a run's start and end cost no thread start, join or wake-up). */
static pthread_mutex_t dog_lock = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t dog_wake = PTHREAD_COND_INITIALIZER;
static int dog_started;
static volatile int dog_active;  /* a run is on and wants the watchdog */
static volatile double stall_limit_s;

static void *watchdog(void *arg) {
    (void)arg;
    double asked_for = -1.0;
    pthread_mutex_lock(&dog_lock);
    for (;;) {
        if (!dog_active) {
            pthread_cond_wait(&dog_wake, &dog_lock);
            continue;
        }
        double limit = stall_limit_s, period = limit / 5 < 0.05 ? limit / 5 : 0.05;
        struct timespec until;
        clock_gettime(CLOCK_REALTIME, &until);
        double t = until.tv_sec + until.tv_nsec * 1e-9 + period;
        until.tv_sec = (time_t)t;
        until.tv_nsec = (long)((t - (double)until.tv_sec) * 1e9);
        pthread_cond_timedwait(&dog_wake, &dog_lock, &until);
        double t0 = resumed_at_s;
        if (dog_active && in_controller && !gone && t0 != asked_for && now_s() - t0 > limit) {
            asked_for = t0;
            pthread_kill(sim_thread_id, SIGUSR1);
        }
    }
    return NULL;
}

static void dog_after_fork(void) {  /* the thread is not in a forked child */
    dog_started = 0;
    dog_active = 0;
    pthread_mutex_init(&dog_lock, NULL);
    pthread_cond_init(&dog_wake, NULL);
}

static void dog_start(double limit_s) {
    pthread_mutex_lock(&dog_lock);
    stall_limit_s = limit_s;
    dog_active = 1;
    if (!dog_started) {
        pthread_t t;
        pthread_attr_t attr;
        pthread_attr_init(&attr);
        pthread_attr_setdetachstate(&attr, PTHREAD_CREATE_DETACHED);
        sigset_t all, old;
        sigfillset(&all);
        pthread_sigmask(SIG_SETMASK, &all, &old);  /* signals are for the other threads */
        if (pthread_create(&t, &attr, watchdog, NULL) == 0) {
            if (!dog_started) pthread_atfork(NULL, NULL, dog_after_fork);
            dog_started = 1;
        }
        pthread_sigmask(SIG_SETMASK, &old, NULL);
        pthread_attr_destroy(&attr);
    } else {
        pthread_cond_signal(&dog_wake);
    }
    pthread_mutex_unlock(&dog_lock);
}

int spinner_inproc_early(void *lib);
static void entry(void) {
    extern char **environ;
    in_controller = 1;
    INIT();  /* the run has started */
    if (prog_lib != NULL && spinner_inproc_early(prog_lib))
        misuse("a call of the kit or the Spinner API before main(), in a global object's constructor: in the "
               "simulator's process the program's constructors run as its library is loaded, before the run, "
               "where nothing can be asked; run it with --isolate, or make the call in main()");
    int rc = user_main(user_argc, user_argv, environ);
    foreign_check();  /* a thread's call that main()'s own calls did not report before main() returned */
    exit_run(rc);
}

/* take_fini: the library's .fini_array (its destructors) into fini_fns, each entry replaced
 * by fini_taken (the array is in the library's RELRO pages on most builds: made writable for
 * the change, read-only again after it). A library with more than MAX_FINI keeps them all. */
static void fini_taken(void) {}
struct relro_query { ElfW(Addr) base; uintptr_t lo, hi; };
static int find_relro(struct dl_phdr_info *info, size_t size, void *data) {
    (void)size;
    struct relro_query *q = data;
    if (info->dlpi_addr != q->base) return 0;
    for (int i = 0; i < info->dlpi_phnum; i++) {
        const ElfW(Phdr) *ph = &info->dlpi_phdr[i];
        if (ph->p_type != PT_GNU_RELRO) continue;
        uintptr_t page = (uintptr_t)sysconf(_SC_PAGESIZE);
        q->lo = (info->dlpi_addr + ph->p_vaddr) & ~(page - 1);  /* as the loader protects it */
        q->hi = (info->dlpi_addr + ph->p_vaddr + ph->p_memsz) & ~(page - 1);
    }
    return 1;
}
static void take_fini(void *lib) {
    struct link_map *lm = NULL;
    ElfW(Addr) at = 0;
    size_t bytes = 0;
    n_fini = 0;
    if (dlinfo(lib, RTLD_DI_LINKMAP, &lm) != 0 || lm == NULL) return;
    for (const ElfW(Dyn) *d = lm->l_ld; d->d_tag != DT_NULL; d++) {
        if (d->d_tag == DT_FINI_ARRAY) at = d->d_un.d_ptr;
        if (d->d_tag == DT_FINI_ARRAYSZ) bytes = d->d_un.d_val;
    }
    size_t n = bytes / sizeof(void (*)(void));
    if (at == 0 || n == 0 || n > MAX_FINI) return;
    void (**fns)(void) = (void (**)(void))(lm->l_addr + at);
    uintptr_t page = (uintptr_t)sysconf(_SC_PAGESIZE);
    uintptr_t lo = (uintptr_t)fns & ~(page - 1);
    uintptr_t hi = ((uintptr_t)(fns + n) + page - 1) & ~(page - 1);
    if (mprotect((void *)lo, hi - lo, PROT_READ | PROT_WRITE) != 0) return;  /* left to dlclose */
    for (size_t i = 0; i < n; i++) {
        fini_fns[i] = fns[i];
        fns[i] = fini_taken;
    }
    n_fini = (int)n;
    struct relro_query q = {lm->l_addr, 0, 0};
    dl_iterate_phdr(find_relro, &q);
    if (lo >= q.lo && hi <= q.hi) mprotect((void *)lo, hi - lo, PROT_READ);
}

/* Open the controller's library: its handle, or NULL (spinner_inproc_error says why). Its
 * constructors' calls are seen (INIT, spinner_running: early_calls) and answered at once. */
static void set_early(void *lib, int early) {
    pthread_mutex_lock(&early_lock);
    int at = -1;
    for (int i = 0; i < MAX_EARLY; i++) {
        if (early_libs[i] == lib) early_libs[i] = NULL;
        if (at < 0 && early_libs[i] == NULL) at = i;
    }
    if (early && at >= 0) early_libs[at] = lib;
    pthread_mutex_unlock(&early_lock);
}

/* A fault in its constructors (or in the loader, or a library it loads) while it is opened: the
 * report to `report_fd` (< 0: a line on stderr), and the process dies by the signal (load_fault);
 * an exit, spinner_fail or misused call there: the same, the process ends with status 70
 * (load_ended).
 * Opens are one at a time (the loader's own lock makes them so anyway). */
static pthread_mutex_t open_lock = PTHREAD_MUTEX_INITIALIZER;

void *spinner_inproc_open(const char *path, int report_fd) {
    static char open_alt_stack[1 << 16];  /* (the opening thread's, during the open) */
    stack_t alt_before;
    pthread_mutex_lock(&open_lock);
    handlers_take();
    alt_stack_on(open_alt_stack, sizeof open_alt_stack, &alt_before);
    load_fd = report_fd, load_path = path, load_thread = pthread_self();
    __atomic_store_n(&load_watch, 1, __ATOMIC_RELEASE);
    opening = 1, early_calls = 0;
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    opening = 0;
    __atomic_store_n(&load_watch, 0, __ATOMIC_RELEASE);
    load_fd = -1, load_path = NULL;
    sigaltstack(&alt_before, NULL);
    handlers_give();
    pthread_mutex_unlock(&open_lock);
    retag_exit_handlers(LOADING_TAG, lib);  /* its constructors' registrations are its */
    if (lib != NULL && early_calls) set_early(lib, 1);
    early_calls = 0;
    return lib;
}

/* Whether `lib`'s constructors called the API as it was loaded: run it isolated. */
int spinner_inproc_early(void *lib) {
    int early = 0;
    pthread_mutex_lock(&early_lock);
    for (int i = 0; i < MAX_EARLY && lib != NULL; i++) early |= early_libs[i] == lib;
    pthread_mutex_unlock(&early_lock);
    return early;
}

const char *spinner_inproc_error(void) {
    const char *e = dlerror();
    return e ? e : "";
}

/* Its exit handlers are dropped as it is unloaded: a library whose constructors registered static
 * destructors (__cxa_atexit, at its load) and that never ran here - run in a child process instead
 * (spinner_inproc_early), or not run at all - left them for the next program's exit to call, into
 * unloaded code (a crash of the simulator's process). */
static void drop_exit_handlers_of(void *lib) { retag_exit_handlers(lib, NULL); }

/* The library's load address (the threads' key: thread_progs). */
static void *lib_base(void *lib) {
    struct link_map *lm = NULL;
    return lib != NULL && dlinfo(lib, RTLD_DI_LINKMAP, &lm) == 0 && lm != NULL ? (void *)lm->l_addr : NULL;
}

/* How many threads `lib`'s program started (thread_begin) are running now. */
int spinner_inproc_threads(void *lib) {
    void *base = lib_base(lib);
    int live = 0;
    pthread_mutex_lock(&thread_progs_lock);
    for (int i = 0; i < MAX_THREAD_PROGS && base != NULL; i++)
        if (thread_progs[i].base == base) live = thread_progs[i].live;
    pthread_mutex_unlock(&thread_progs_lock);
    return live;
}

/* Unload `lib`: 0 (dlclose's -1 if it failed), or the number of its program's threads still
 * running, for which it stays loaded (their code must stay mapped) with our signal handlers
 * installed (their faults are named: stray_fault), both until the last of them ends (it gives the
 * handlers back; the library stays). */
int spinner_inproc_close(void *lib) {
    set_early(lib, 0);
    drop_exit_handlers_of(lib);
    void *base = lib_base(lib);
    int live = 0, take = 0;
    pthread_mutex_lock(&thread_progs_lock);
    for (int i = 0; i < MAX_THREAD_PROGS && base != NULL; i++)
        if (thread_progs[i].base == base && (live = thread_progs[i].live) > 0 && !thread_progs[i].kept)
            thread_progs[i].kept = take = 1;
    if (take) handlers_take();  /* (under the lock: its last thread gives them back after this) */
    pthread_mutex_unlock(&thread_progs_lock);
    return live > 0 ? live : dlclose(lib);
}

/* Where the simulator reads the requests (spinner_inproc_resume says how many bytes). */
unsigned char *spinner_inproc_requests(void) { return out_buf; }

int spinner_inproc_exit_code(void) { return exit_code; }

/* Whether the controller ended, and the bytes of its last requests (kept until the next
 * resume: a fault's report can be read again). */
int spinner_inproc_gone(void) { return gone; }
long spinner_inproc_pending(void) { return (long)out_len; }

/* Prepare a run of `lib`'s main(argc, argv) (`stall_s` > 0: with the watchdog; `report_fd`: where a
 * fault in a thread of the program's own is reported before the process dies by it, the
 * supervision's report file, < 0: a line on stderr; thread_fault). 0, or 72 without main(), 12
 * without memory for its stack, 16 while another run is on (in another thread:
 * spinner_inproc_finish ends a run). The controller starts at the first resume (whose reply is the
 * run's INIT message). */
static int run_active;  /* one run at a time in a process (the state above is the run's) */

int spinner_inproc_start(void *lib, int argc, char **argv, double stall_s, int report_fd) {
    if (__atomic_exchange_n(&run_active, 1, __ATOMIC_ACQ_REL)) return 16;  /* EBUSY */
    user_main = (main_fn)dlsym(lib, "main");
    prog_lib = lib;
    Dl_info info;  /* (the program's threads: their faults are the run's, thread_fault) */
    prog_base = user_main != NULL && dladdr((void *)user_main, &info) ? info.dli_fbase : NULL;
    prog_path = prog_base != NULL ? info.dli_fname : NULL;
    run_fd = report_fd;
    isr_count = isr_depth = 0;  /* (a handler that faulted never returned) */
    irq_masked = irq_held = irq_mask_unsent = irq_unmasking = 0, irq_mask_ra = NULL, mask_msg_len = 0;
    memset(isr_fn, 0, sizeof isr_fn);
    memset(isr_stopping, 0, sizeof isr_stopping);
    memset(isr_latched, 0, sizeof isr_latched);
    kit_before_wait = NULL, in_kit_hook = 0;
    if (user_main == NULL) {
        __atomic_store_n(&run_active, 0, __ATOMIC_RELEASE);
        return 72;
    }
    size_t page = (size_t)sysconf(_SC_PAGESIZE);
    if (stack_mem == NULL) {  /* `ulimit -s` as for a main thread (8 MB if unlimited) */
        struct rlimit rl;
        stack_size = 8u << 20;
        if (getrlimit(RLIMIT_STACK, &rl) == 0 && rl.rlim_cur != RLIM_INFINITY &&
            rl.rlim_cur >= 1u << 16)
            stack_size = ((size_t)rl.rlim_cur + page - 1) / page * page;
        void *m = mmap(NULL, stack_size + page, PROT_READ | PROT_WRITE,
                       MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
        if (m == MAP_FAILED) {
            __atomic_store_n(&run_active, 0, __ATOMIC_RELEASE);
            return 12;
        }
        mprotect(m, page, PROT_NONE);  /* the guard page: an overflow faults there */
        stack_mem = m;
    }
    stack_lo = (uintptr_t)stack_mem + page;
    stack_hi = stack_lo + stack_size;
    user_argc = argc;
    user_argv = argv;
    /* a fresh API state for this run */
    finished = inited = run_over = 0;
    thread_exit_status = -1, thread_exit_quick = 0;
    foreign_calls = 0;
    out_len = 0;
    rep_buf = rep_more = NULL, rep_len = rep_pos = rep_more_len = 0;
    gone = 0, exit_code = 0, in_controller = 0;
    last_speed = last_angle = speed_mps = steer_rad = 0.0;
    last_time_s = last_speed_val = 0.0;
    now_known = 0, now_time_s = 0.0, mask_msg_ra = NULL;  /* (spinner_now's answer is the run's) */
    last_pos[0] = last_pos[1] = last_pos[2] = 0.0;
    f_speed_norm = f_speed_denorm = f_turn_norm = f_diff_norm = NULL;
    n_helpers = 0;
    take_fini(lib);
    ctx_make((void *)stack_lo, stack_size);
    pthread_sigmask(SIG_BLOCK, NULL, &run_mask);
    sim_thread_id = pthread_self();
    install_handlers();
    if (stall_s > 0) dog_start(stall_s);
    return 0;
}

/* Hand the controller `reply` (n bytes, then n_more bytes at `more`) and run it to its next
 * waiting call: the number of request bytes at spinner_inproc_requests(), or -(that + 1)
 * when the controller ended (it returned, exited or faulted: a fault's report is among the
 * requests). The reply is read in place: it must stay valid (and unchanged) until then. */
static long resume_with(const unsigned char *reply, size_t n, const unsigned char *more,
                        size_t n_more) {
    if (gone) return -1;
    rep_buf = reply, rep_len = n, rep_pos = 0;
    rep_more = n_more ? more : NULL, rep_more_len = n_more;
    out_len = 0;
    resumed_at_s = now_s();
    TO_CO();
    in_controller = 0;
    rep_buf = rep_more = NULL, rep_len = rep_pos = rep_more_len = 0;
    return gone ? -(long)out_len - 1 : (long)out_len;
}

long spinner_inproc_resume(const unsigned char *reply, size_t n) {
    return resume_with(reply, n, NULL, 0);
}

/* The same with a camera frame's reply: status OK and the `n` image bytes (n < 2^32, as
 * every reply length): the header is made here and the image read where it is, so the
 * simulator need not join them. */
long spinner_inproc_resume_image(const unsigned char *image, size_t n) {
    frame_head[0] = ST_OK, frame_head[1] = (uint32_t)n;
    return resume_with((const unsigned char *)frame_head, sizeof frame_head, image, n);
}

/* End the run's coroutine (wherever it is), restore the signal handlers. */
void spinner_inproc_finish(void) {
    gone = finished = run_over = 1;
    drop_exit_handlers_of(prog_lib);  /* its handlers a fault or the simulator's end left: unloaded next */
    n_fini = 0;
    end_helpers();
    in_controller = 0;
    pthread_mutex_lock(&dog_lock);  /* it sends only under the lock: none comes after this */
    dog_active = 0;  /* the watchdog goes back to sleep at its next look */
    pthread_mutex_unlock(&dog_lock);
    restore_handlers();
    fflush(stdout);
    fflush(stderr);
    run_fd = -1;
    __atomic_store_n(&run_active, 0, __ATOMIC_RELEASE);
}
#endif
