//! The seed of each run: SplitMix64 over the master seed.

/// The seed of run `run` under master seed `master`: the `run`-th output of SplitMix64
/// (Steele, Lea & Flood 2014) seeded with `master`. Use it to replay one run alone.
pub fn run_seed(master: u64, run: usize) -> u64 {
    let mut z = master.wrapping_add(
        (run as u64)
            .wrapping_add(1)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15),
    );
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_seed_is_splitmix64() {
        // SplitMix64 seeded with 0: first outputs (reference values of the algorithm).
        assert_eq!(run_seed(0, 0), 0xE220_A839_7B1D_CDAF);
        assert_eq!(run_seed(0, 1), 0x6E78_9E6A_A1B9_65F4);
    }
}
