/* The driver's side of the lockstep firmware's shared-memory exchange (BF_SITL_SHM_FD).
 *
 * aerobat compiles this file with the host C compiler into a small shared library (shm.py,
 * cached by the source's hash) and calls it from the compiled lockstep loop and from Python.
 * The firmware's side is in lockstep.patch (sitl.c, simShm*()); the layout below must match
 * its SHM_OFF_* definitions.
 *
 * Protocol: one 4096-byte region. A sequence word per direction counts the packets published;
 * the writer copies its packet, stores the sequence word (sequentially consistent: a full
 * barrier on x86), then wakes the reader's futex only if the reader's sleeping flag is set. The
 * reader spins with a pause instruction for an adaptive budget, then sets its sleeping flag,
 * re-checks the word and futex-waits on it with a timeout. After a wait that ended while
 * spinning the budget is twice that wait plus 2 us (at most the maximum); after one that had to
 * sleep it halves (the peer was not running: spinning on only takes a core from it); every 32nd
 * wait spins the maximum. The driver's wait for the motor packet spins the whole maximum (see
 * aerobat_shm_wait_motor), or, asked to measure (a negative spin_ns), chooses between spinning and
 * sleeping at once by measuring which steps faster (see choose_spin). No wait here is without a
 * timeout: a timeout returns 0 and the caller (Python's watchdog) decides.
 *
 * The last three functions are the firmware's side, for the tests' stand-in firmware.
 */
#include <linux/futex.h>
#include <stdint.h>
#include <string.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#define SHM_SIZE 4096
#define SHM_MAGIC 0x31485341u /* "ASH1" */
#define SHM_OFF_MAGIC 0
#define SHM_OFF_STATE_SEQ 64  /* driver: state packets published */
#define SHM_OFF_RC_SEQ 68     /* driver: RC packets published */
#define SHM_OFF_MOTOR_WAIT 72 /* driver: 1 while it sleeps on MOTOR_SEQ */
#define SHM_OFF_DRIVER_SPIN_NS 80 /* driver: uint64, ns it spun waiting for motor packets */
#define SHM_OFF_DRIVER_ADAPT 88 /* driver: uint64 spin budget [ns], uint32 waits */
#define SHM_OFF_MOTOR_SEQ 128 /* firmware: the STATE_SEQ its motor packet answers */
#define SHM_OFF_STATE_WAIT 132 /* firmware: 1 while it sleeps on STATE_SEQ */
#define SHM_OFF_SPIN_NS 136   /* firmware: uint64, ns it spun waiting for state packets */
#define SHM_OFF_FIRMWARE_ADAPT 144 /* the stand-in firmware: uint64 spin budget [ns], uint32 waits */
#define SHM_OFF_STATE 256     /* state packet, 144 bytes */
#define SHM_OFF_RC 448        /* RC packet, 40 bytes */
#define SHM_OFF_MOTOR 512     /* motor packet, 76 bytes */
#define SHM_OFF_DRIVER_POLICY 1024 /* driver: struct spin_policy (choose_spin) */
#define SHM_STATE_MAX 192
#define SHM_RC_MAX 64
#define SHM_MOTOR_MAX 256

#define WORD(shm, offset) ((uint32_t *)((uint8_t *)(shm) + (offset)))

static inline void cpu_relax(void)
{
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    __asm__ __volatile__("yield");
#endif
}

static int64_t monotonic_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static void wake(uint32_t *word, const uint32_t *sleeping)
{
    if (__atomic_load_n(sleeping, __ATOMIC_SEQ_CST)) {
        syscall(SYS_futex, word, FUTEX_WAKE, 1, NULL, NULL, 0);
    }
}

static void add_ns(uint64_t *counter, int64_t ns)
{
    __atomic_store_n(counter, *counter + (uint64_t)ns, __ATOMIC_RELAXED); /* one writer */
}

/* Wait until *word differs from (differ != 0) or equals (differ == 0) value; 1 if so, 0 after timeout_ns.
 * Spin up to the adaptive budget at adapt (at most max_spin_ns, at least min_spin_ns), then sleep; the
 * time spent spinning is added to *spun. */
static int wait_word(uint32_t *word, uint32_t *sleeping, uint64_t *spun, uint8_t *adapt, uint32_t value, int differ,
                     int64_t max_spin_ns, int64_t min_spin_ns, int64_t timeout_ns)
{
    uint64_t *budget = (uint64_t *)adapt;
    uint32_t *waits = (uint32_t *)(adapt + 8);
    const int64_t start = monotonic_ns();
    int64_t spin_ns = ++*waits % 32 == 0 ? max_spin_ns : (int64_t)*budget;
    if (spin_ns > max_spin_ns) {
        spin_ns = max_spin_ns;
    }
    if (spin_ns < min_spin_ns) {
        spin_ns = min_spin_ns;
    }
    int64_t now = start;
    int spinning = 1;
    for (;;) {
        for (int i = 0; i < 16; i++) {
            const uint32_t seen = __atomic_load_n(word, __ATOMIC_ACQUIRE);
            if ((seen != value) == (differ != 0)) {
                if (spinning) {
                    const int64_t waited = monotonic_ns() - start;
                    add_ns(spun, waited);
                    *budget = (uint64_t)(2 * waited + 2000 < max_spin_ns ? 2 * waited + 2000 : max_spin_ns);
                }
                return 1;
            }
            cpu_relax();
        }
        now = monotonic_ns();
        if (now - start >= timeout_ns) {
            if (spinning) {
                add_ns(spun, now - start);
                *budget /= 2;
            }
            return 0;
        }
        if (spinning && now - start < spin_ns) {
            continue;
        }
        if (spinning) {
            add_ns(spun, now - start);
            *budget /= 2;
            spinning = 0;
        }
        __atomic_store_n(sleeping, 1, __ATOMIC_SEQ_CST);
        const uint32_t seen = __atomic_load_n(word, __ATOMIC_SEQ_CST);
        if ((seen != value) != (differ != 0)) {
            const int64_t left = timeout_ns - (now - start);
            const struct timespec slice = {left / 1000000000, left % 1000000000};
            syscall(SYS_futex, word, FUTEX_WAIT, seen, &slice, NULL, 0);
        }
        __atomic_store_n(sleeping, 0, __ATOMIC_RELAXED);
    }
}

/* The driver's measured choice between spinning and sleeping (choose_spin): step times per mode.
 * Python reads the counters (shm.py, _POLICY_STRUCT): keep the two layouts alike. */
struct spin_policy {
    int64_t epoch_start_ns; /* when this epoch began */
    int64_t last_ns;        /* the last wait's start */
    int64_t epoch_ns;       /* wall time this epoch lasts (at least) */
    uint32_t epoch_seq;     /* the state packet this epoch began at */
    uint32_t last_seq;      /* the state packet of the last wait */
    uint32_t home;          /* the mode flown between probes: 0 spin, 1 sleep */
    uint32_t mode;          /* the mode of this epoch (home, or the other while probing) */
    uint32_t until_probe;   /* epochs at home before the next probe */
    uint32_t backoff;       /* epochs between probes, doubled after each probe the other mode lost */
    double cost_ns[2];      /* wall time per step measured in each mode [ns] (home: smoothed) */
    uint64_t steps[2];      /* steps flown in each mode */
    uint64_t switches;      /* times the home mode changed */
    uint64_t probes;        /* epochs spent trying the other mode */
};

#define POLICY_EPOCH_NS 25000000 /* an epoch lasts 25 ms of wall time: several scheduler ticks */
#define POLICY_BACKOFF_MIN 4     /* epochs between probes after a switch */
#define POLICY_BACKOFF_MAX 32    /* at most (0.8 s): a load that changes is noticed within a second */
#define POLICY_PAUSE_NS 1000000  /* a pause longer than this and than PAUSE_STEP_NS a step: not the exchange */
#define POLICY_PAUSE_STEP_NS 100000
#define POLICY_MARGIN_SPIN 0.95  /* spinning takes over when it steps 5 % faster */
#define POLICY_MARGIN_SLEEP 0.8  /* sleeping when it steps 20 % faster: spinning under load is bimodal (a
                                  * trial at 14x or at 60x, docs/performance.md), and a 25 ms epoch of
                                  * sleeping beats one of the bad spinning often enough to mislead */

/* The driver's spin budget for the wait for the answer to state packet seq [ns] at time now [ns, the
 * monotonic clock; the tests give their own]: max_spin_ns in the spin mode, 0 in the sleep mode.
 *
 * Spinning hands a packet over in a fraction of a microsecond when both sides have a core; on a
 * loaded machine it takes the core the peer (or another process) needs, and sleeping at once can
 * be faster. Which is true is measured, not configured: steps (state packets) are counted in
 * epochs of 25 ms of wall time (several scheduler ticks, so one preemption does not decide), and
 * an epoch's wall time per step is the cost of its mode. The driver flies its home mode and, after
 * `backoff` epochs, probes the other for one epoch; if that steps faster (spinning by 5 %, sleeping
 * by 20 %) it becomes home, else the probes grow rarer (up to one per 32 epochs, 0.8 s). A pause between two waits
 * (the driver's Python between compiled calls, a phase change: over 1 ms and over 100 us a step)
 * restarts the epoch, so it measures the exchange, not the pauses. Waits the driver skips (the
 * answer came while it worked) count as steps of the mode in force. A new region may start from
 * what an earlier one learned (shm.py writes home, costs, backoff and the epochs until the next probe
 * before the first wait). */
int64_t aerobat_shm_choose_spin(void *policy, int64_t seq64, int64_t max_spin_ns, int64_t now)
{
    struct spin_policy *p = (struct spin_policy *)policy;
    const uint32_t seq = (uint32_t)seq64;
    if (p->epoch_ns == 0) { /* the region's first wait */
        p->epoch_ns = POLICY_EPOCH_NS;
        if (p->backoff == 0) {
            p->backoff = POLICY_BACKOFF_MIN;
        }
        if (p->until_probe == 0 || p->until_probe > p->backoff) {
            p->until_probe = p->backoff;
        }
        p->mode = p->home;
        p->epoch_start_ns = p->last_ns = now;
        p->epoch_seq = p->last_seq = seq;
    }
    const uint32_t since = seq - p->last_seq;
    const int64_t gap = now - p->last_ns;
    if (gap > POLICY_PAUSE_NS && gap > POLICY_PAUSE_STEP_NS * (int64_t)since) {
        p->epoch_start_ns = now;
        p->epoch_seq = seq;
    }
    p->steps[p->mode] += since;
    p->last_ns = now;
    p->last_seq = seq;
    const uint32_t flown = seq - p->epoch_seq;
    if (now - p->epoch_start_ns >= p->epoch_ns && flown > 0) {
        const double cost = (double)(now - p->epoch_start_ns) / (double)flown;
        if (p->mode == p->home) {
            p->cost_ns[p->home] = p->cost_ns[p->home] > 0.0 ? 0.5 * (p->cost_ns[p->home] + cost) : cost;
            if (--p->until_probe == 0) {
                p->mode = 1 - p->home;
                p->probes++;
            }
        } else {
            p->cost_ns[p->mode] = cost;
            if (cost < (p->mode == 1 ? POLICY_MARGIN_SLEEP : POLICY_MARGIN_SPIN) * p->cost_ns[p->home]) {
                p->home = p->mode;
                p->backoff = POLICY_BACKOFF_MIN;
                p->switches++;
            } else {
                p->backoff = p->backoff * 2 < POLICY_BACKOFF_MAX ? p->backoff * 2 : POLICY_BACKOFF_MAX;
            }
            p->until_probe = p->backoff;
            p->mode = p->home;
        }
        p->epoch_start_ns = now;
        p->epoch_seq = seq;
    }
    return p->mode == 0 ? max_spin_ns : 0;
}

static int64_t choose_spin(struct spin_policy *p, uint32_t seq, int64_t max_spin_ns)
{
    return aerobat_shm_choose_spin(p, seq, max_spin_ns, monotonic_ns());
}

/* Initialise a fresh region (before the firmware maps it). */
void aerobat_shm_init(void *shm)
{
    memset(shm, 0, SHM_SIZE);
    __atomic_store_n(WORD(shm, SHM_OFF_MAGIC), SHM_MAGIC, __ATOMIC_SEQ_CST);
}

/* Publish a state packet of n bytes; returns its sequence number (-1: n too large). */
int64_t aerobat_shm_publish_state(void *shm, const void *state, int64_t n)
{
    if (n < 0 || n > SHM_STATE_MAX) {
        return -1;
    }
    memcpy((uint8_t *)shm + SHM_OFF_STATE, state, (size_t)n);
    uint32_t *seq = WORD(shm, SHM_OFF_STATE_SEQ);
    const uint32_t next = __atomic_load_n(seq, __ATOMIC_RELAXED) + 1;
    __atomic_store_n(seq, next, __ATOMIC_SEQ_CST);
    wake(seq, WORD(shm, SHM_OFF_STATE_WAIT));
    return next;
}

/* Publish an RC packet of n bytes; the firmware takes the latest with the next state packet. */
int64_t aerobat_shm_publish_rc(void *shm, const void *rc, int64_t n)
{
    if (n < 0 || n > SHM_RC_MAX) {
        return -1;
    }
    memcpy((uint8_t *)shm + SHM_OFF_RC, rc, (size_t)n);
    uint32_t *seq = WORD(shm, SHM_OFF_RC_SEQ);
    const uint32_t next = __atomic_load_n(seq, __ATOMIC_RELAXED) + 1;
    __atomic_store_n(seq, next, __ATOMIC_RELEASE); /* the state packet's store orders it for the reader */
    return next;
}

/* Wait for the motor packet answering the last state packet and copy its n bytes into motor.
 * Returns n, or 0 when none came within timeout_ns (spinning spin_ns, then asleep). The driver spins
 * its whole budget, not an adaptive part of it: a firmware step that runs a slow task takes several
 * microseconds, and a driver asleep by then costs a futex wake on both sides (the firmware, kept
 * waiting for the late driver, falls asleep too; docs/performance.md, issue 27). A negative spin_ns
 * measures instead whether spinning (up to -spin_ns) or sleeping at once steps faster (choose_spin). */
int64_t aerobat_shm_wait_motor(void *shm, void *motor, int64_t n, int64_t spin_ns, int64_t timeout_ns)
{
    if (n < 0 || n > SHM_MOTOR_MAX) {
        return -1;
    }
    const uint32_t target = __atomic_load_n(WORD(shm, SHM_OFF_STATE_SEQ), __ATOMIC_RELAXED);
    if (spin_ns < 0) {
        spin_ns = choose_spin((struct spin_policy *)((uint8_t *)shm + SHM_OFF_DRIVER_POLICY), target, -spin_ns);
    }
    if (!wait_word(WORD(shm, SHM_OFF_MOTOR_SEQ), WORD(shm, SHM_OFF_MOTOR_WAIT),
                   (uint64_t *)((uint8_t *)shm + SHM_OFF_DRIVER_SPIN_NS), (uint8_t *)shm + SHM_OFF_DRIVER_ADAPT,
                   target, 0, spin_ns, spin_ns, timeout_ns)) {
        return 0;
    }
    memcpy(motor, (uint8_t *)shm + SHM_OFF_MOTOR, (size_t)n);
    return n;
}

/* The motor packet answering the last state packet, if it came: its n bytes copied into motor and n
 * returned; 0 if it has not come yet (no wait). Lets the driver work while the firmware computes. */
int64_t aerobat_shm_poll_motor(void *shm, void *motor, int64_t n)
{
    if (n < 0 || n > SHM_MOTOR_MAX) {
        return -1;
    }
    const uint32_t target = __atomic_load_n(WORD(shm, SHM_OFF_STATE_SEQ), __ATOMIC_RELAXED);
    if (__atomic_load_n(WORD(shm, SHM_OFF_MOTOR_SEQ), __ATOMIC_ACQUIRE) != target) {
        return 0;
    }
    memcpy(motor, (uint8_t *)shm + SHM_OFF_MOTOR, (size_t)n);
    return n;
}

/* Firmware side: wait for a state packet after sequence number seen; returns the new sequence
 * number (its n bytes copied into state), or -1 after timeout_ns. */
int64_t aerobat_shm_wait_state(void *shm, void *state, int64_t n, int64_t seen, int64_t spin_ns, int64_t timeout_ns)
{
    uint32_t *seq = WORD(shm, SHM_OFF_STATE_SEQ);
    if (n < 0 || n > SHM_STATE_MAX
        || !wait_word(seq, WORD(shm, SHM_OFF_STATE_WAIT), (uint64_t *)((uint8_t *)shm + SHM_OFF_SPIN_NS),
                      (uint8_t *)shm + SHM_OFF_FIRMWARE_ADAPT, (uint32_t)seen, 1, spin_ns, 0, timeout_ns)) {
        return -1;
    }
    const uint32_t now = __atomic_load_n(seq, __ATOMIC_ACQUIRE);
    memcpy(state, (uint8_t *)shm + SHM_OFF_STATE, (size_t)n);
    return now;
}

/* Firmware side: the RC sequence number now, its packet copied into rc when it is not seen. */
int64_t aerobat_shm_take_rc(void *shm, void *rc, int64_t n, int64_t seen)
{
    const uint32_t now = __atomic_load_n(WORD(shm, SHM_OFF_RC_SEQ), __ATOMIC_ACQUIRE);
    if (now != (uint32_t)seen && n >= 0 && n <= SHM_RC_MAX) {
        memcpy(rc, (uint8_t *)shm + SHM_OFF_RC, (size_t)n);
    }
    return now;
}

/* Firmware side: publish the motor packet answering state sequence number answered. */
void aerobat_shm_publish_motor(void *shm, const void *motor, int64_t n, int64_t answered)
{
    if (n < 0 || n > SHM_MOTOR_MAX) {
        return;
    }
    memcpy((uint8_t *)shm + SHM_OFF_MOTOR, motor, (size_t)n);
    __atomic_store_n(WORD(shm, SHM_OFF_MOTOR_SEQ), (uint32_t)answered, __ATOMIC_SEQ_CST);
    wake(WORD(shm, SHM_OFF_MOTOR_SEQ), WORD(shm, SHM_OFF_MOTOR_WAIT));
}
