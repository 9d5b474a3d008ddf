#![no_main]
//! A session directory: manifest, index and frame container (`impactcam::fuzzing::session`).
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    // One scratch directory per input: files from the last input never leak into this one.
    let Ok(dir) = tempfile::tempdir() else { return };
    impactcam::fuzzing::session(data, dir.path());
});
