//! The instruction sets the CPU ray queries run in. The build targets x86-64's baseline (SSE2),
//! so that the binary runs on any x86-64 processor; the queries are compiled a second time for
//! x86-64-v3 (AVX2, FMA, BMI1/2, LZCNT, MOVBE, F16C: every x86-64 processor since about 2015)
//! and that copy runs where the processor has those features. The answers are the same bytes:
//! Rust never contracts a multiply and an add into an FMA by itself, so the same operations
//! round the same way; what changes is their encoding (three-operand VEX forms, fewer register
//! moves), SSE4.1's rounding and BMI. With the walk's start inlined into it, the queries
//! were 4–29 % faster than the baseline build's on the standard 1920×1080 sets (BENCHMARKS.md).
//! The CPU volume renderers (`raystream-cpu`'s `dvr::march_v3` and `cinematic::pixel_v3`) run
//! each pixel in the same instruction set, chosen here too.
//!
//! Hand-written rather than through a multiversioning crate: each copy is one function whose
//! callees are `#[inline(always)]` into it, dispatched per chunk of rays or per pixel, and its
//! test compares the two copies byte for byte.

use std::sync::atomic::{AtomicU8, Ordering};

/// An instruction set the CPU queries can run in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// The build's own target (x86-64: SSE2), on any processor.
    Baseline,
    /// x86-64-v3: AVX2, FMA, BMI1/2, LZCNT, MOVBE and F16C.
    X86_64V3,
}

/// 0: not chosen (the best the processor has); otherwise `Isa as u8 + 1`.
static CHOSEN: AtomicU8 = AtomicU8::new(0);

impl Isa {
    pub const ALL: [Isa; 2] = [Isa::Baseline, Isa::X86_64V3];

    /// Its name, as `RAYSTREAM_CPU_ISA` and `trace --json` spell it.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Baseline => "baseline",
            Isa::X86_64V3 => "x86-64-v3",
        }
    }

    /// Whether this processor can run it.
    pub fn available(self) -> bool {
        match self {
            Isa::Baseline => true,
            Isa::X86_64V3 => v3_detected(),
        }
    }

    /// The best instruction set this processor has.
    pub fn detected() -> Isa {
        if Isa::X86_64V3.available() {
            Isa::X86_64V3
        } else {
            Isa::Baseline
        }
    }

    /// The instruction set the queries (and the CPU volume renderers' pixels) run in: the one
    /// chosen with [`Isa::choose`], else
    /// [`Isa::detected`].
    pub fn current() -> Isa {
        match CHOSEN.load(Ordering::Relaxed) {
            1 => Isa::Baseline,
            2 => Isa::X86_64V3,
            _ => Isa::detected(),
        }
    }

    /// Runs the CPU queries of this process in `self` from now on; an error where the
    /// processor lacks it.
    pub fn choose(self) -> Result<(), String> {
        if !self.available() {
            return Err(format!(
                "this processor cannot run {} (it has {})",
                self.name(),
                Isa::detected().name()
            ));
        }
        CHOSEN.store(self as u8 + 1, Ordering::Relaxed);
        Ok(())
    }
}

impl std::str::FromStr for Isa {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Isa::ALL
            .into_iter()
            .find(|isa| isa.name() == s)
            .ok_or_else(|| {
                format!("unknown instruction set '{s}' (expected baseline or x86-64-v3)")
            })
    }
}

#[cfg(target_arch = "x86_64")]
fn v3_detected() -> bool {
    // Cached by the standard library after the first call: a load and a test.
    std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
        && std::arch::is_x86_feature_detected!("bmi1")
        && std::arch::is_x86_feature_detected!("bmi2")
        && std::arch::is_x86_feature_detected!("lzcnt")
        && std::arch::is_x86_feature_detected!("movbe")
        && std::arch::is_x86_feature_detected!("f16c")
}

#[cfg(not(target_arch = "x86_64"))]
fn v3_detected() -> bool {
    false
}
