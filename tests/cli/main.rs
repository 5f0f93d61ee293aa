//! The `l3` executable end to end, one test binary: simulate → train → render → eval and
//! `l3 serve` (`cli`), `l3 bench --quick` (`bench`), `l3 eval --catalogue` (`catalogue`),
//! `l3 eval --colorchecker` on simulated captures (`colorchecker`),
//! `l3 sensors` and `l3 render --data-dir`'s choice of table by the DNG's camera (`cameras`),
//! sensors by catalogue name or by a TOML beside its curves (`sensors`), `l3 sfr` on image
//! files (`sfr`), `l3 eval --scielab` on float XYZ TIFFs (`scielab`), `l3 render` to JPEG
//! (`jpeg`), the spatial metrics of `l3 eval` on a simulated chart (`spatial`), and the exit
//! codes of bad flags, designs and missing files (`exit_codes`).

mod bench;
mod cameras;
mod catalogue;
mod cli;
mod colorchecker;
mod exit_codes;
mod fit;
mod jpeg;
mod scielab;
mod sensors;
mod sfr;
mod spatial;
mod support;
mod usage;
