//! Fuzz target `table_file`: the body is `l3::fuzzing::fuzz_table_file`, shared with
//! `tests/fuzz_regressions/main.rs`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    l3::fuzzing::fuzz_table_file(data);
});
