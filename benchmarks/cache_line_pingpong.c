/* What one lockstep step's two hand-overs cost at least, by how the waiting side waits.
 *
 * Two threads pass a counter back and forth through two words on separate cache lines; the time
 * per round trip is the floor under a step of the Betaflight plant's shared-memory exchange
 * (docs/performance.md, issue 27), whatever the firmware and the physics do in between:
 *
 *   spin, two cores      both wait spinning with `pause` (the exchange with firmware.spin_us > 0)
 *   futex, two cores     both sleep on a futex and are woken by the other (spin_us = 0)
 *   futex, one core      the same with both threads pinned to one core
 *   yield, one core      both pinned to one core, waiting in a sched_yield() loop: the cheapest
 *                        hand-over that leaves the other core to a second instance
 *
 * and the cost of one clock_gettime(CLOCK_MONOTONIC). Each line also gives the process's CPU time
 * ÷ wall time over the round trips (2.0: both threads kept a core busy).
 *
 *     gcc -O2 -pthread benchmarks/cache_line_pingpong.c -o /tmp/pingpong && /tmp/pingpong
 */
#define _GNU_SOURCE
#include <linux/futex.h>
#include <pthread.h>
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

enum wait_kind { SPIN, FUTEX, YIELD };

static volatile uint32_t ping __attribute__((aligned(64)));
static volatile uint32_t pong __attribute__((aligned(64)));
static enum wait_kind kind;
static int peer_cpu;
static uint32_t rounds;

static double seconds(const struct timespec *a, const struct timespec *b)
{
    return (double)(b->tv_sec - a->tv_sec) + 1e-9 * (double)(b->tv_nsec - a->tv_nsec);
}

static void pin(int cpu)
{
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cpu, &set);
    pthread_setaffinity_np(pthread_self(), sizeof(set), &set);
}

static void wait_for(volatile uint32_t *word, uint32_t value)
{
    while (__atomic_load_n(word, __ATOMIC_ACQUIRE) != value) {
        if (kind == SPIN) {
            __builtin_ia32_pause();
        } else if (kind == YIELD) {
            sched_yield();
        } else {
            syscall(SYS_futex, word, FUTEX_WAIT, value - 1, NULL, NULL, 0);
        }
    }
}

static void post(volatile uint32_t *word, uint32_t value)
{
    __atomic_store_n(word, value, __ATOMIC_SEQ_CST);
    if (kind == FUTEX) {
        syscall(SYS_futex, word, FUTEX_WAKE, 1, NULL, NULL, 0);
    }
}

static void *peer(void *unused)
{
    (void)unused;
    pin(peer_cpu);
    for (uint32_t i = 1; i <= rounds; i++) {
        wait_for(&ping, i);
        post(&pong, i);
    }
    return NULL;
}

static void round_trips(const char *name, enum wait_kind how, int cpu, int other_cpu, uint32_t n)
{
    pthread_t thread;
    struct timespec start, end, cpu0, cpu1;
    kind = how;
    peer_cpu = other_cpu;
    rounds = n;
    ping = 0;
    pong = 0;
    pin(cpu);
    pthread_create(&thread, NULL, peer, NULL);
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &cpu0);
    clock_gettime(CLOCK_MONOTONIC, &start);
    for (uint32_t i = 1; i <= n; i++) {
        post(&ping, i);
        wait_for(&pong, i);
    }
    clock_gettime(CLOCK_MONOTONIC, &end);
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &cpu1);
    pthread_join(thread, NULL);
    printf("%-18s round trip %7.3f us  (CPU / wall %.2f)\n", name, 1e6 * seconds(&start, &end) / n,
           seconds(&cpu0, &cpu1) / seconds(&start, &end));
}

int main(void)
{
    const int two_cores = sysconf(_SC_NPROCESSORS_ONLN) >= 2;
    round_trips("spin, two cores", SPIN, 0, two_cores ? 1 : 0, two_cores ? 2000000u : 2000u);
    round_trips("futex, two cores", FUTEX, 0, two_cores ? 1 : 0, 200000u);
    round_trips("futex, one core", FUTEX, 0, 0, 200000u);
    round_trips("yield, one core", YIELD, 0, 0, 200000u);
    struct timespec start, end;
    clock_gettime(CLOCK_MONOTONIC, &start);
    for (uint32_t i = 0; i < 2000000u; i++) {
        clock_gettime(CLOCK_MONOTONIC, &end);
    }
    printf("clock_gettime(CLOCK_MONOTONIC): %.1f ns\n", 1e9 * seconds(&start, &end) / 2000000u);
    return 0;
}
