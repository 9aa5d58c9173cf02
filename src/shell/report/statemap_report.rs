//! The state map in the shell: its printout (`study compare`, `study diagnose`) and its two
//! Parquet tables.

use crate::orchestration::diagnosis::statemap::{self, StateMap};
use crate::shell::formats::parquet_write;
use crate::shell::formats::parquet_write::Column;
use std::io::Write;

/// Where in state space the residual lies: per residual, the share each state's terms explain
/// and their strongest terms, then the one sentence.
pub fn print(o: &mut dyn Write, map: &StateMap) -> std::io::Result<()> {
    writeln!(o)?;
    writeln!(o, "  where in state space ({} samples; R^2 of a sparse regression on each state's terms, then its terms with their R^2 alone; docs/model.md §8):", map.samples)?;
    for r in statemap::REGRESSED {
        if map.by_state(r).is_empty() {
            continue;
        }
        writeln!(o, "  {}:", r.label())?;
        for reg in map.by_state(r) {
            let terms: Vec<String> = reg
                .terms
                .iter()
                .take(3)
                .map(|t| format!("{} ({:.2})", t.formula(), t.alone))
                .collect();
            let st = reg.state.map_or("all states", |s| s.label());
            writeln!(
                o,
                "    {:<28} R^2 {:>5.2}  {}",
                st,
                reg.r2,
                if terms.is_empty() {
                    "-".to_string()
                } else {
                    terms.join(", ")
                }
            )?;
        }
        for (_, m) in map.memory.iter().filter(|(res, _)| *res == r) {
            writeln!(
                o,
                "    {:<28} R^2 {:>5.2}  {}",
                m.kind.name(),
                m.r2,
                crate::orchestration::diagnosis::statemap::memory_text(m)
            )?;
        }
    }
    match map.sentence() {
        Some(s) => {
            writeln!(o, "  -> {s}")?;
            if let Some(e) = map.expression() {
                writeln!(o, "     as an expression to fit (docs/formats.md, \"Expressions\"), in a model file:")?;
                for line in e.lines() {
                    writeln!(o, "       {line}")?;
                }
            }
        }
        None => writeln!(o, "  -> no state's terms explain the residual (R^2 < {}): noise, or an effect neither a static term nor an oscillator holds", statemap::MIN_R2)?,
    }
    Ok(())
}

/// The state map's tables: `statemap.parquet` (per state and bin, each residual's mean and rms)
/// and `stateterms.parquet` (per regression, its R² and the terms kept).
pub fn write(
    dir: &std::path::Path,
    map: &StateMap,
    meta: &[(String, String)],
) -> anyhow::Result<()> {
    use statemap::Residual;
    let b = &map.bins;
    let f = |g: &dyn Fn(&statemap::MapBin) -> f64| Column::F64(b.iter().map(g).collect());
    let mut cols = vec![
        (
            "state".to_string(),
            Column::Str(b.iter().map(|x| x.state.name().to_string()).collect()),
        ),
        ("bin_lo".to_string(), f(&|x| x.lo)),
        ("bin_hi".to_string(), f(&|x| x.hi)),
        ("scale".to_string(), f(&|x| x.scale)),
        (
            "scale_unit".to_string(),
            Column::Str(b.iter().map(|x| x.state.scale_unit().to_string()).collect()),
        ),
        (
            "samples".to_string(),
            Column::U32(b.iter().map(|x| x.samples as u32).collect()),
        ),
    ];
    for (i, r) in Residual::ALL.iter().enumerate() {
        cols.push((format!("mean_{}", r.name()), f(&|x| x.mean[i])));
        cols.push((format!("rms_{}", r.name()), f(&|x| x.rms[i])));
    }
    parquet_write::write_table(&dir.join("statemap.parquet"), cols, meta)?;
    parquet_write::write_table(
        &dir.join("stateterms.parquet"),
        state_term_rows(map).into_columns(),
        meta,
    )
}

/// The rows of `stateterms.parquet`: every regression's terms (one row without a term when it
/// kept none), then the terms with memory (the filter's `f_n_hz` and `zeta`; its gain in `coef`:
/// for the oscillator the mass, kg); `named` marks the row the map's sentence names.
#[derive(Default)]
struct StateTermRows {
    residual: Vec<String>,
    states: Vec<String>,
    r2: Vec<f64>,
    term_state: Vec<String>,
    term: Vec<String>,
    coef: Vec<f64>,
    r2_alone: Vec<f64>,
    named: Vec<bool>,
    /// A term with memory's natural frequency (Hz) and damping ratio; NaN for a static term.
    f_n_hz: Vec<f64>,
    zeta: Vec<f64>,
}

impl StateTermRows {
    #[allow(clippy::too_many_arguments)]
    fn push(
        &mut self,
        residual: statemap::Residual,
        states: &str,
        r2: f64,
        term_state: &str,
        term: String,
        coef: f64,
        alone: f64,
        named: bool,
    ) {
        self.residual.push(residual.name().into());
        self.states.push(states.into());
        self.r2.push(r2);
        self.term_state.push(term_state.into());
        self.term.push(term);
        self.coef.push(coef);
        self.r2_alone.push(alone);
        self.named.push(named);
        self.f_n_hz.push(f64::NAN);
        self.zeta.push(f64::NAN);
    }

    fn into_columns(self) -> Vec<(String, Column)> {
        vec![
            ("residual".into(), Column::Str(self.residual)),
            ("states".into(), Column::Str(self.states)),
            ("r2".into(), Column::F64(self.r2)),
            ("term_state".into(), Column::Str(self.term_state)),
            ("term".into(), Column::Str(self.term)),
            ("coef".into(), Column::F64(self.coef)),
            ("r2_alone".into(), Column::F64(self.r2_alone)),
            ("named".into(), Column::Bool(self.named)),
            ("f_n_hz".into(), Column::F64(self.f_n_hz)),
            ("zeta".into(), Column::F64(self.zeta)),
        ]
    }
}

fn state_term_rows(map: &StateMap) -> StateTermRows {
    use statemap::Named;
    let named = map.named();
    let mut rows = StateTermRows::default();
    for g in map.per_state.iter().flatten().chain(&map.joint) {
        let states = g.state.map_or("all", |s| s.name());
        if g.terms.is_empty() {
            rows.push(
                g.residual,
                states,
                g.r2,
                "",
                String::new(),
                f64::NAN,
                f64::NAN,
                false,
            );
        }
        for t in &g.terms {
            let is = matches!(named, Some(Named::Static(ng, nt)) if std::ptr::eq(ng, g) && std::ptr::eq(nt, t));
            rows.push(
                g.residual,
                states,
                g.r2,
                t.state.name(),
                t.formula(),
                t.coef,
                t.alone,
                is,
            );
        }
    }
    for (r, m) in &map.memory {
        let st = m.kind.state().name();
        let term = format!("{} (f_n {:.3} Hz, ζ {:.4})", m.kind.name(), m.f_n, m.zeta);
        rows.push(
            *r,
            st,
            m.r2,
            st,
            term,
            m.gain,
            m.r2,
            matches!(named, Some(Named::Memory(_, n)) if std::ptr::eq(n, m)),
        );
        (rows.f_n_hz[rows.r2.len() - 1], rows.zeta[rows.r2.len() - 1]) = (m.f_n, m.zeta);
    }
    rows
}
