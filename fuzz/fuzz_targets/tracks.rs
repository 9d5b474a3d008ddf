#![no_main]
//! A tracks CSV through the analysis (`impactcam::fuzzing::tracks`).
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    // One scratch directory per input: files from the last input never leak into this one.
    let Ok(dir) = tempfile::tempdir() else { return };
    impactcam::fuzzing::tracks(data, &dir.path().join("in.csv"));
});
