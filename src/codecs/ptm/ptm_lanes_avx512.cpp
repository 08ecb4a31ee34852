// ptm's lane coder, the SIMD decoder built for AVX-512 (ptm_lanes_simd.h): the same 256-bit
// vectors and instructions as the AVX2 build, which the compiler may encode with AVX-512VL's
// 32 vector registers and mask registers. The AVX2 build spills about a quarter of its step
// loop's instructions to the stack for want of registers; on the codec study's inputs this
// build decoded 3-10 % faster (docs/benchmarks.md, "twelfth session").
#define TESSERA_LANES_ISA avx512
#define TESSERA_LANES_AVX512 1
#define TESSERA_LANES_TARGET __attribute__((target("avx2,avx512f,avx512vl,avx512bw,avx512dq")))
#include "ptm/ptm_lanes_simd.h"
