/* The reset handler of the emulated Cortex-M4 (QEMU mps2-an386): enable the FPU (CPACR),
   then newlib's _start (rdimon: semihosting stdio and files, argv from QEMU). */
extern void _start(void);
extern unsigned long __stack_top;

void Reset_Handler(void) {
  *(volatile unsigned long *)0xE000ED88 |= 0xFUL << 20; /* CP10, CP11: full access */
  __asm volatile("dsb\n isb");
  _start();
}

static void Default_Handler(void) {
  for (;;) {
  }
}

__attribute__((section(".isr_vector"), used)) void (*const vectors[16])(void) = {
    (void (*)(void))&__stack_top, Reset_Handler, Default_Handler, Default_Handler,
    Default_Handler, Default_Handler, Default_Handler, 0, 0, 0, 0,
    Default_Handler, Default_Handler, 0, Default_Handler, Default_Handler,
};
