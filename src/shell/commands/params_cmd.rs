//! `study params`: the parameter registry as a table.

use crate::kernel::effects::LIBRARY;
use crate::kernel::params::{Component, ModelParams};
use crate::shell::cli::ParamsArgs;
use crate::shell::BadInput;
use std::io::Write;

pub fn run(args: &ParamsArgs) -> anyhow::Result<()> {
    if args.effects {
        let mut out = std::io::stdout().lock();
        writeln!(
            out,
            "{:<18} {:<26} {:<28} adds",
            "effect", "family", "a diagnosis frees"
        )?;
        for e in LIBRARY {
            writeln!(
                out,
                "{:<18} {:<26} {:<28} {}",
                e.name,
                e.family,
                e.free().join(", "),
                e.summary
            )?;
        }
        writeln!(out, "\nSwitch one on with its table [model.NAME] in a model, run or study file; its parameters: study params NAME.")?;
        return Ok(());
    }
    let component = match &args.component {
        Some(c) => Some(Component::parse(c).ok_or_else(|| {
            let all: Vec<&str> = ModelParams::components().map(Component::name).collect();
            BadInput(format!(
                "unknown component `{c}`; expected one of: {}",
                all.join(", ")
            ))
        })?),
        None => None,
    };
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "{:<30} {:<12} {:>14} {:<16} {:<10} meaning",
        "parameter", "unit", "default", "range", "source"
    )?;
    for p in ModelParams::registry().filter(|p| component.is_none_or(|c| c == p.component)) {
        writeln!(
            out,
            "{:<30} {:<12} {:>14} {:<16} {:<10} {}",
            p.path(),
            p.unit,
            format!("{}", p.default),
            p.range.to_string(),
            p.source.to_string(),
            p.doc
        )?;
    }
    if component.is_none_or(|c| c == Component::Servovalve) {
        writeln!(out, "{:<30} {:<12} {:>14} {:<16} {:<7} Valve flow law: square-root orifice, or the linear counter-example.", "servovalve.law", "-", "orifice", "orifice|linear", "paper")?;
    }
    if component
        == Some(Component::Effect(
            crate::kernel::params::EffectId::Expression,
        ))
    {
        writeln!(out, "\nThe slots hold the parameters a model file's [model.expression] names (`c = {{ value, unit, range }}`), which --free, --set and a study's variables take by name (expression.c); docs/formats.md, \"Expressions\".")?;
    }
    Ok(())
}
