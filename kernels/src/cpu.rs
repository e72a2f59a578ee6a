//! Runtime CPU-feature dispatch of the hot kernels: one binary, built for the baseline x86-64
//! (SSE2), runs P2G and G2P through copies compiled for AVX2 where the CPU has it.
//!
//! The rule that keeps results bit-identical whichever copy runs: only features that change the
//! instructions, never the arithmetic. AVX2 (with the VEX encodings and SSE4.1's `roundsd` it
//! implies) performs the same IEEE-754 operations in the same order; FMA is not enabled, and Rust
//! never contracts a multiply and an add on its own, so no rounding moves. The tests of
//! `transfer.rs` compare the two copies bit for bit.

/// Whether this CPU runs the AVX2 copies (std caches the CPUID answer after the first call).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub fn has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}
