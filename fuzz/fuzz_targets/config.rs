#![no_main]
//! The config parser and validation (`impactcam::fuzzing::config`).
libfuzzer_sys::fuzz_target!(|data: &[u8]| impactcam::fuzzing::config(data));
