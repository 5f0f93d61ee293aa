//! The `l3` executable end to end, one test binary: simulate → train → render → eval and
//! `l3 serve` (`cli`), `l3 bench --quick` (`bench`), and `l3 eval --colorchecker` on simulated captures
//! (`colorchecker`).

mod bench;
mod cli;
mod colorchecker;
