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
 * aerobat_shm_wait_motor). No wait here is without a timeout: a timeout returns 0 and the caller
 * (Python's watchdog) decides.
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
 * waiting for the late driver, falls asleep too; docs/performance.md, issue 27). */
int64_t aerobat_shm_wait_motor(void *shm, void *motor, int64_t n, int64_t spin_ns, int64_t timeout_ns)
{
    if (n < 0 || n > SHM_MOTOR_MAX) {
        return -1;
    }
    const uint32_t target = __atomic_load_n(WORD(shm, SHM_OFF_STATE_SEQ), __ATOMIC_RELAXED);
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
