#![no_main]
//! The TIFF stack reader (`impactcam::fuzzing::tiff`).
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    // One scratch directory per input: files from the last input never leak into this one.
    let Ok(dir) = tempfile::tempdir() else { return };
    impactcam::fuzzing::tiff(data, &dir.path().join("in.tif"));
});
