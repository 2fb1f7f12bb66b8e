/* bench.c: instructions per sample of the rbf-core C library's step on the
 * STM32F405 under QEMU (`-icount shift=0`: SysTick on the 168 MHz core
 * clock counts 0.168 ticks per instruction), the same sample stream as the
 * Rust loop of qemu-bench (1 kHz, 12.5 deg/h, the loop temperature rising
 * 0.0001 degC a sample), and the stack one load and the steps take.
 * Built twice by `cargo xtask bench-fw`: BENCH_AXES 1 (rbf_gyro_*, the
 * K = 32, D = 3 model qemu-bench times) and 3 (rbf_imu_*, its K = 32, D = 3
 * shared basis), so that each image holds only what its loop links.
 *
 *   bench MODEL.bin */
#include <math.h>
#include <stdint.h>
#include <stdio.h>

#include "rbf_core.h"

#ifndef BENCH_AXES
#define BENCH_AXES 1
#endif
#define SAMPLES 2000u
#define TICKS_PER_KILO_INSTRUCTION 168u
#define PAINT_WORDS 2048u
#define PAINT 0xA5C3E1F0u

#if BENCH_AXES == 1
static _Alignas(RBF_GYRO_STATE_ALIGN) uint8_t state[RBF_GYRO_STATE_SIZE];
#else
static _Alignas(RBF_IMU_STATE_ALIGN) uint8_t state[RBF_IMU_STATE_SIZE];
#endif
static uint8_t blob[8192];
static size_t blob_len;
static volatile uint32_t *const SYST_CSR = (volatile uint32_t *)0xE000E010u;
static volatile uint32_t *const SYST_RVR = (volatile uint32_t *)0xE000E014u;
static volatile uint32_t *const SYST_CVR = (volatile uint32_t *)0xE000E018u;
static volatile float sink;
static unsigned long instructions;
static int status;

/* The load and SAMPLES steps; the steps' instructions into `instructions`. */
static __attribute__((noinline)) void load_and_step(void) {
#if BENCH_AXES == 1
    status = rbf_gyro_load(state, sizeof state, blob, blob_len, 1000.0f);
    rbf_gyro_sample_t s = {.dt_s = 0.001f, .rate_dph = 12.5f};
    rbf_output_t out;
#else
    status = rbf_imu_load(state, sizeof state, blob, blob_len, 1000.0f);
    rbf_imu_sample_t s = {.dt_s = 0.001f, .rates_dph = {12.5f, -3.0f, 7.25f}};
    rbf_imu_output_t out;
#endif
    float temp_c = 20.0f;
    for (int t = 0; t < RBF_THERMOMETERS; t++) s.temps_c[t] = NAN;
    uint32_t start = *SYST_CVR;
    for (unsigned i = 0; i < SAMPLES; i++) {
        temp_c += 0.0001f;
        s.temps_c[RBF_LOOP_THERMOMETER] = temp_c;
#if BENCH_AXES == 1
        rbf_gyro_step(state, sizeof state, &s, &out);
        sink = out.rate_comp_dph;
#else
        for (int a = 0; a < RBF_AXES; a++) s.loop_temps_c[a] = temp_c;
        rbf_imu_step(state, sizeof state, &s, &out);
        sink = out.axes[0].rate_comp_dph;
#endif
    }
    uint32_t ticks = (start - *SYST_CVR) & 0x00FFFFFFu;
    instructions = (unsigned long)ticks * 1000u / TICKS_PER_KILO_INSTRUCTION / SAMPLES;
}

int main(int argc, char **argv) {
    if (argc != 2) return 1;
    FILE *f = fopen(argv[1], "rb");
    if (!f) return 1;
    blob_len = fread(blob, 1, sizeof blob, f);
    fclose(f);
    *SYST_RVR = 0x00FFFFFFu;
    *SYST_CVR = 0;
    *SYST_CSR = 5u; /* enabled, core clock, no interrupt */
    /* Paint the stack below this frame, run, and find the deepest word written. */
    uint32_t *sp;
    __asm__ volatile("mov %0, sp" : "=r"(sp));
    uint32_t *floor = sp - PAINT_WORDS;
    for (uint32_t *w = floor; w < sp - 16; w++) *w = PAINT;
    load_and_step();
    uint32_t *w = floor;
    while (w < sp && *w == PAINT) w++;
    if (status != RBF_OK) {
        printf("bench: %s\n", rbf_status_message(status));
        return 2;
    }
    printf("c_library axes=%d instructions_per_sample %lu stack_bytes %lu\n", BENCH_AXES, instructions,
           (unsigned long)((uint8_t *)sp - (uint8_t *)w));
    return 0;
}
