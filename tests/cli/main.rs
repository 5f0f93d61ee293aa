//! The `l3` executable end to end, one test binary: simulate → train → render → eval and
//! `l3 serve` (`cli`), and `l3 bench --quick` (`bench`).

mod bench;
mod cli;
