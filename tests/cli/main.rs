//! The `l3` executable end to end, one test binary: simulate → train → render → eval and
//! `l3 serve` (`cli`), `l3 bench --quick` (`bench`), `l3 eval --catalogue` (`catalogue`),
//! `l3 sensors` and `l3 render --data-dir`'s choice of table by the DNG's camera (`cameras`),
//! sensors by catalogue name or by a TOML beside its curves (`sensors`), and `l3 sfr` on image
//! files (`sfr`), and `l3 render` to JPEG (`jpeg`).

mod bench;
mod cameras;
mod catalogue;
mod cli;
mod jpeg;
mod sensors;
mod sfr;
mod support;
