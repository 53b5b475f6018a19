/*
 * texsense's C ABI (crates/mcu/include/texsense.h) run from C, on the host (gcc) and on an
 * emulated Cortex-M4 (arm-none-eabi-gcc, QEMU with semihosting: the files are the host's).
 * Built and run by tests/test_mcu.py:
 *
 *   test_mat DIR    reads DIR/mat.bin (a blob of `texsense export mcu`) and DIR/frames.bin
 *                   (the frames of a recording), writes DIR/out.bin (every frame's values
 *                   and codes), runs the fault cases and prints one line per check.
 *
 * frames.bin: "TXSNFRM1", N (u32), T (u32), then per frame: dt (f32, s), the readings
 * (N f32, pF), their validity (N bytes). out.bin: per frame the values (N f32) and the codes
 * (N bytes). On the Cortex-M4 the frames are also timed with SysTick (with QEMU's -icount the
 * ticks count instructions; a loop of a known number of instructions calibrates them).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "texsense.h"

static int failures = 0;

static void check(const char *what, int32_t got, int32_t want) {
  int ok = got == want;
  printf("check %s: %s (%s)\n", what, (const char *)ts_status_name(got),
         ok ? "ok" : "FAILED");
  failures += !ok;
}

static uint8_t *read_file(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) {
    printf("cannot open %s\n", path);
    exit(2);
  }
  size_t cap = 1 << 16, n = 0, got;
  uint8_t *buf = malloc(cap);
  while (buf && (got = fread(buf + n, 1, cap - n, f)) > 0) {
    n += got;
    if (n == cap) {
      cap *= 2;
      buf = realloc(buf, cap);
    }
  }
  fclose(f);
  if (!buf) {
    printf("out of memory reading %s\n", path);
    exit(2);
  }
  *len = n;
  return buf;
}

#if defined(__ARM_ARCH)
/* SysTick: a 24-bit down-counter at the processor clock */
#define SYST_CSR (*(volatile uint32_t *)0xE000E010)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018)
static void ticks_start(void) {
  SYST_RVR = 0xFFFFFF;
  SYST_CVR = 0;
  SYST_CSR = 5; /* enabled, processor clock, no interrupt */
}
static uint32_t ticks_now(void) { return SYST_CVR; }
static uint32_t ticks_since(uint32_t before) { return (before - SYST_CVR) & 0xFFFFFF; }
/* 2 instructions per turn (subs, bne) */
static uint32_t calibration_ticks(uint32_t turns) {
  uint32_t before = ticks_now();
  __asm volatile("1: subs %0, %0, #1\n bne 1b\n" : "+r"(turns) : : "cc");
  return ticks_since(before);
}
#else
static void ticks_start(void) {}
static uint32_t ticks_now(void) { return 0; }
static uint32_t ticks_since(uint32_t before) { return before; }
static uint32_t calibration_ticks(uint32_t turns) { return turns * 0; }
#endif

/* The fault cases: damaged, foreign and cut blobs, wrong element count, memory too small,
   bad arguments; every one refused with its code. */
static void faults(const uint8_t *blob, size_t len, uint32_t n, size_t need) {
  size_t bytes = 0;
  uint8_t *copy = malloc(len + 8);
  uint8_t *mem = malloc(need + 8);
  ts_mat *mat = NULL;
  if (!copy || !mem) {
    printf("out of memory\n");
    exit(2);
  }
  memcpy(copy, blob, len);
  copy[len / 2] ^= 0x40; /* a bit flipped in a stage */
  check("damaged blob", ts_mem_size(copy, len, &bytes), TS_ERR_CHECKSUM);
  check("damaged blob (init)", ts_init(mem, need, copy, len, n, &mat), TS_ERR_CHECKSUM);
  memcpy(copy, blob, len);
  copy[8] = (uint8_t)(TS_BLOB_VERSION + 1); /* another format version */
  check("other version", ts_init(mem, need, copy, len, n, &mat), TS_ERR_VERSION);
  memcpy(copy, blob, len);
  check("cut short", ts_init(mem, need, copy, len - 4, n, &mat), TS_ERR_LENGTH);
  memset(copy, 0, 16);
  check("not a blob", ts_init(mem, need, copy, len, n, &mat), TS_ERR_MAGIC);
  memcpy(copy + 2, blob, len); /* 2 bytes off the alignment */
  check("misaligned blob", ts_init(mem, need, copy + 2, len, n, &mat), TS_ERR_ALIGN);
  check("wrong element count", ts_init(mem, need, blob, len, n + 1, &mat), TS_ERR_ELEMENTS);
  check("memory too small", ts_init(mem, need - 1, blob, len, n, &mat), TS_ERR_MEMORY);
  check("NULL memory", ts_init(NULL, need, blob, len, n, &mat), TS_ERR_NULL);
  check("NULL blob", ts_mem_size(NULL, len, &bytes), TS_ERR_NULL);
  memset(mem, 0, need);
  float r[1] = {1.0f}, v[1];
  check("not initialised", ts_step((ts_mat *)mem, r, NULL, 0.1f, v, NULL), TS_ERR_STATE);
  check("init", ts_init(mem, need, blob, len, n, &mat), TS_OK);
  check("elements", (int32_t)ts_n_elements(mat) - (int32_t)n, 0);
  float *x = calloc(n, sizeof(float)), *y = calloc(n, sizeof(float));
  check("negative time step", ts_step(mat, x, NULL, -0.1f, y, NULL), TS_ERR_TIME);
  check("time step not a number", ts_step(mat, x, NULL, NAN, y, NULL), TS_ERR_TIME);
  check("NULL readings", ts_step(mat, NULL, NULL, 0.1f, y, NULL), TS_ERR_NULL);
  /* NaN and zero readings: a step, every code a short or break, values NaN (no history) */
  uint8_t *codes = malloc(n);
  for (uint32_t i = 0; i < n; i++) x[i] = NAN;
  check("NaN readings", ts_step(mat, x, NULL, 0.1f, y, codes), TS_OK);
  int shorts = 0;
  for (uint32_t i = 0; i < n; i++) shorts += codes[i] == TS_CODE_SHORT_OR_BREAK && isnan(y[i]);
  check("NaN readings are shorts or breaks", shorts - (int32_t)n, 0);
  memset(x, 0, n * sizeof(float));
  check("zero readings", ts_step(mat, x, NULL, 0.1f, y, codes), TS_OK);
  shorts = 0;
  for (uint32_t i = 0; i < n; i++) shorts += codes[i] == TS_CODE_SHORT_OR_BREAK;
  check("zero readings are shorts or breaks", shorts - (int32_t)n, 0);
  check("reset", ts_reset(mat), TS_OK);
  free(codes);
  free(x);
  free(y);
  free(copy);
  free(mem);
}

int main(int argc, char **argv) {
  char path[512];
  if (argc < 2) {
    printf("usage: test_mat DIR\n");
    return 2;
  }
  size_t len, flen;
  snprintf(path, sizeof path, "%s/mat.bin", argv[1]);
  uint8_t *blob = read_file(path, &len);
  size_t need = 0;
  check("mem size", ts_mem_size(blob, len, &need), TS_OK);
  snprintf(path, sizeof path, "%s/frames.bin", argv[1]);
  uint8_t *frames = read_file(path, &flen);
  uint32_t n, t;
  if (flen < 16 || memcmp(frames, "TXSNFRM1", 8) != 0) {
    printf("%s is not a frames file\n", path);
    return 2;
  }
  memcpy(&n, frames + 8, 4);
  memcpy(&t, frames + 12, 4);
  size_t frame_bytes = 4 + 5 * (size_t)n;
  if (flen != 16 + (size_t)t * frame_bytes) {
    printf("%s: %u frames of %u elements do not fit its length\n", path, (unsigned)t,
           (unsigned)n);
    return 2;
  }
  ticks_start();
  uint8_t *mem = malloc(need);
  ts_mat *mat = NULL;
  uint32_t before = ticks_now();
  check("init", ts_init(mem, need, blob, len, n, &mat), TS_OK);
  uint32_t init_ticks = ticks_since(before);
  if (!mat) return 1;
  snprintf(path, sizeof path, "%s/out.bin", argv[1]);
  FILE *out = fopen(path, "wb");
  float *readings = malloc(n * sizeof(float)), *values = malloc(n * sizeof(float));
  uint8_t *codes = malloc(n);
  uint64_t step_ticks = 0;
  int step_failed = 0;
  for (uint32_t k = 0; k < t; k++) {
    const uint8_t *f = frames + 16 + (size_t)k * frame_bytes;
    float dt;
    memcpy(&dt, f, 4);
    memcpy(readings, f + 4, n * sizeof(float));
    before = ticks_now();
    int32_t s = ts_step(mat, readings, f + 4 + 4 * (size_t)n, dt, values, codes);
    step_ticks += ticks_since(before);
    step_failed += s != TS_OK;
    fwrite(values, sizeof(float), n, out);
    fwrite(codes, 1, n, out);
  }
  fclose(out);
  check("every frame stepped", step_failed, 0);
  printf("memory %lu bytes, blob %lu bytes, %u elements, %u frames\n", (unsigned long)need,
         (unsigned long)len, (unsigned)n, (unsigned)t);
  printf("ticks init %lu step %llu calibration %lu per 2000000 instructions\n",
         (unsigned long)init_ticks, (unsigned long long)step_ticks,
         (unsigned long)calibration_ticks(1000000));
  faults(blob, len, n, need);
  printf("%s\n", failures ? "SOME CHECKS FAILED" : "ALL CHECKS PASSED");
  return failures != 0;
}
