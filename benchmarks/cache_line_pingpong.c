/* A cache line's round trip between two cores: the floor under any shared-memory hand-over.
 *
 * Two threads pass a counter back and forth through two words on separate cache lines, both
 * spinning with `pause`; the time per round trip is what one lockstep step's two hand-overs cost
 * at least (docs/performance.md, issue 27). Also the cost of one clock_gettime(CLOCK_MONOTONIC).
 *
 *     gcc -O2 -pthread benchmarks/cache_line_pingpong.c -o /tmp/pingpong && /tmp/pingpong
 */
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <time.h>

#define ROUNDS 2000000u

static volatile uint32_t ping __attribute__((aligned(64)));
static volatile uint32_t pong __attribute__((aligned(64)));

static double seconds(const struct timespec *a, const struct timespec *b)
{
    return (double)(b->tv_sec - a->tv_sec) + 1e-9 * (double)(b->tv_nsec - a->tv_nsec);
}

static void *peer(void *unused)
{
    (void)unused;
    for (uint32_t i = 1; i <= ROUNDS; i++) {
        while (__atomic_load_n(&ping, __ATOMIC_ACQUIRE) != i) {
            __builtin_ia32_pause();
        }
        __atomic_store_n(&pong, i, __ATOMIC_RELEASE);
    }
    return NULL;
}

int main(void)
{
    pthread_t thread;
    struct timespec start, end;
    pthread_create(&thread, NULL, peer, NULL);
    clock_gettime(CLOCK_MONOTONIC, &start);
    for (uint32_t i = 1; i <= ROUNDS; i++) {
        __atomic_store_n(&ping, i, __ATOMIC_RELEASE);
        while (__atomic_load_n(&pong, __ATOMIC_ACQUIRE) != i) {
            __builtin_ia32_pause();
        }
    }
    clock_gettime(CLOCK_MONOTONIC, &end);
    pthread_join(thread, NULL);
    printf("round trip of a cache line between two threads: %.3f us\n", 1e6 * seconds(&start, &end) / ROUNDS);
    clock_gettime(CLOCK_MONOTONIC, &start);
    for (uint32_t i = 0; i < ROUNDS; i++) {
        clock_gettime(CLOCK_MONOTONIC, &end);
    }
    printf("clock_gettime(CLOCK_MONOTONIC): %.1f ns\n", 1e9 * seconds(&start, &end) / ROUNDS);
    return 0;
}
