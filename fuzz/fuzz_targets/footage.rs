#![no_main]
//! Other cameras' files: Photron CIH + MRAW, CINE, FMF, a numbered image
//! (`impactcam::fuzzing::footage`).
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    // One scratch directory per input: files from the last input never leak into this one.
    let Ok(dir) = tempfile::tempdir() else { return };
    impactcam::fuzzing::footage(data, dir.path());
});
