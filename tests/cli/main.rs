//! The `l3` executable end to end, one test binary: simulate → train → render → eval and
//! `l3 serve` (`cli`), `l3 sensors` and `l3 render --data-dir`'s choice of table by the DNG's
//! camera (`cameras`), and `l3 bench --quick` (`bench`).

mod bench;
mod cameras;
mod cli;
