/* Reset for a C program on the STM32F405 (QEMU's netduinoplus2): the
 * vector table, the FPU on, .data copied from flash, then newlib's _start
 * (librdimon's crt0: .bss zeroed, semihosting files and arguments, main,
 * exit through semihosting). Only the replay test image uses it: a real
 * firmware has its own startup. */
#include <stdint.h>

extern uint32_t __stack, __data_start__, __data_end__, __data_load__;
extern void _start(void);
void Reset_Handler(void);

static void halt(void) {
    for (;;) {
    }
}

/* Initial stack pointer, reset, then NMI … SysTick: none expected. */
__attribute__((section(".isr_vector"), used)) static const void *const vectors[16] = {
    &__stack, (void *)Reset_Handler, (void *)halt, (void *)halt, (void *)halt, (void *)halt,
    (void *)halt, 0, 0, 0, 0, (void *)halt, (void *)halt, 0, (void *)halt, (void *)halt,
};

void Reset_Handler(void) {
    /* CPACR: full access to CP10 and CP11 (the FPU) before any float instruction. */
    volatile uint32_t *cpacr = (volatile uint32_t *)0xE000ED88u;
    *cpacr |= 0xFu << 20;
    __asm__ volatile("dsb\n\tisb" ::: "memory");
    uint32_t *src = &__data_load__;
    for (uint32_t *dst = &__data_start__; dst < &__data_end__;) *dst++ = *src++;
    _start();
    halt();
}
