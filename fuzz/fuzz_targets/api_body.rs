#![no_main]
//! The daemon's `POST /api/experiments` body (`impactcam::fuzzing::api_body`).
libfuzzer_sys::fuzz_target!(|data: &[u8]| impactcam::fuzzing::api_body(data));
