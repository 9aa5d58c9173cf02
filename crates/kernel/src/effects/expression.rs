//! Effect `expression`: physics written as expressions in a model file, no rebuild. Each of its
//! hooks ([`Hook`]: a force on the platen, a flow into either chamber, the valve opening, the
//! supply pressure, a recorded channel) may be given an expression ([`crate::expr`]) of that
//! hook's quantities, the time `t` since the start of the run and up to [`SLOTS`] named
//! parameters; a hook without one is left alone.
//!
//! ```toml
//! [model.expression]
//! force = "-c2 * v * abs(v)"                                # N on the platen
//! c2 = { value = 4.0e4, unit = "N·s²/m²", range = [0, 1e9] }  # a named parameter
//! ```
//!
//! The parameters' values sit in the slots `p1`..`p32` of this effect's table, in the order their
//! names were first declared; the model layer (`params`) keeps the names, their units and their
//! ranges, so that `expression.c2` is a parameter like any other (fits, studies, diagnoses).
//! Where a hook's expression is not given, the effect is neutral there; where the effect is off
//! in a lane, it is neutral in that lane. An expression runs on the CPU (an interpreted program,
//! [`crate::expr::Program`]); the CUDA kernel does not have it, and a study with it on takes the
//! CPU engine.

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, PlantView, Stage};
use crate::expr::{ExprError, Program};
use crate::param_table::{params, Range};
use std::sync::Arc;

/// The effect's entry in the library. Its free parameters are the named ones its expressions
/// read (the model's, not the table's: a diagnosis asks the model).
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "expression",
    summary: "forces, flows, openings, supply pressure or channels written as expressions",
    params: Params::FIELDS,
    stages: &[Stage::free(&[])],
};

/// How many named parameters the expressions of one process may declare.
pub const SLOTS: usize = 32;

params! {
    /// Effect `expression`: the values of its named parameters, by slot (a model file names them).
    pub struct Params {
        p1: "-", "", 0.0, Range::any(), Chosen, "Slot 1 of the expressions' named parameters [chosen: none until a model file names it].";
        p2: "-", "", 0.0, Range::any(), Chosen, "Slot 2 (see p1) [chosen].";
        p3: "-", "", 0.0, Range::any(), Chosen, "Slot 3 (see p1) [chosen].";
        p4: "-", "", 0.0, Range::any(), Chosen, "Slot 4 (see p1) [chosen].";
        p5: "-", "", 0.0, Range::any(), Chosen, "Slot 5 (see p1) [chosen].";
        p6: "-", "", 0.0, Range::any(), Chosen, "Slot 6 (see p1) [chosen].";
        p7: "-", "", 0.0, Range::any(), Chosen, "Slot 7 (see p1) [chosen].";
        p8: "-", "", 0.0, Range::any(), Chosen, "Slot 8 (see p1) [chosen].";
        p9: "-", "", 0.0, Range::any(), Chosen, "Slot 9 (see p1) [chosen].";
        p10: "-", "", 0.0, Range::any(), Chosen, "Slot 10 (see p1) [chosen].";
        p11: "-", "", 0.0, Range::any(), Chosen, "Slot 11 (see p1) [chosen].";
        p12: "-", "", 0.0, Range::any(), Chosen, "Slot 12 (see p1) [chosen].";
        p13: "-", "", 0.0, Range::any(), Chosen, "Slot 13 (see p1) [chosen].";
        p14: "-", "", 0.0, Range::any(), Chosen, "Slot 14 (see p1) [chosen].";
        p15: "-", "", 0.0, Range::any(), Chosen, "Slot 15 (see p1) [chosen].";
        p16: "-", "", 0.0, Range::any(), Chosen, "Slot 16 (see p1) [chosen].";
        p17: "-", "", 0.0, Range::any(), Chosen, "Slot 17 (see p1) [chosen].";
        p18: "-", "", 0.0, Range::any(), Chosen, "Slot 18 (see p1) [chosen].";
        p19: "-", "", 0.0, Range::any(), Chosen, "Slot 19 (see p1) [chosen].";
        p20: "-", "", 0.0, Range::any(), Chosen, "Slot 20 (see p1) [chosen].";
        p21: "-", "", 0.0, Range::any(), Chosen, "Slot 21 (see p1) [chosen].";
        p22: "-", "", 0.0, Range::any(), Chosen, "Slot 22 (see p1) [chosen].";
        p23: "-", "", 0.0, Range::any(), Chosen, "Slot 23 (see p1) [chosen].";
        p24: "-", "", 0.0, Range::any(), Chosen, "Slot 24 (see p1) [chosen].";
        p25: "-", "", 0.0, Range::any(), Chosen, "Slot 25 (see p1) [chosen].";
        p26: "-", "", 0.0, Range::any(), Chosen, "Slot 26 (see p1) [chosen].";
        p27: "-", "", 0.0, Range::any(), Chosen, "Slot 27 (see p1) [chosen].";
        p28: "-", "", 0.0, Range::any(), Chosen, "Slot 28 (see p1) [chosen].";
        p29: "-", "", 0.0, Range::any(), Chosen, "Slot 29 (see p1) [chosen].";
        p30: "-", "", 0.0, Range::any(), Chosen, "Slot 30 (see p1) [chosen].";
        p31: "-", "", 0.0, Range::any(), Chosen, "Slot 31 (see p1) [chosen].";
        p32: "-", "", 0.0, Range::any(), Chosen, "Slot 32 (see p1) [chosen].";
    }
}

impl Params {
    fn slots(&self) -> [f64; SLOTS] {
        [
            self.p1, self.p2, self.p3, self.p4, self.p5, self.p6, self.p7, self.p8, self.p9,
            self.p10, self.p11, self.p12, self.p13, self.p14, self.p15, self.p16, self.p17,
            self.p18, self.p19, self.p20, self.p21, self.p22, self.p23, self.p24, self.p25,
            self.p26, self.p27, self.p28, self.p29, self.p30, self.p31, self.p32,
        ]
    }
}

/// Where an expression acts: its model-file key, the quantities it reads, what it gives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Hook {
    /// A force on the platen, N (positive extends), of its displacement `y` and velocity `v`.
    Force,
    /// A flow into chamber 1 (cap side) of each actuator, m³/s, of the chamber pressures `p1`,
    /// `p2` and the supply pressure `ps` (Pa).
    Flow1,
    /// A flow into chamber 2 (rod side) of each actuator, m³/s, of `p1`, `p2`, `ps`.
    Flow2,
    /// The valve opening, m, from the spool command `x` (m).
    Opening,
    /// The supply pressure the valves see, Pa, from the nominal `ps`.
    Supply,
    /// The recorded acceleration (m/s²), displacement (m) and force (N), from the plant's `a`,
    /// `d`, `f`.
    Accel,
    Disp,
    SensedForce,
}

impl Hook {
    pub const ALL: [Hook; 8] = [
        Hook::Force,
        Hook::Flow1,
        Hook::Flow2,
        Hook::Opening,
        Hook::Supply,
        Hook::Accel,
        Hook::Disp,
        Hook::SensedForce,
    ];

    /// Its key in `[model.expression]`.
    pub fn key(self) -> &'static str {
        match self {
            Hook::Force => "force",
            Hook::Flow1 => "flow_1",
            Hook::Flow2 => "flow_2",
            Hook::Opening => "opening",
            Hook::Supply => "supply",
            Hook::Accel => "accel_channel",
            Hook::Disp => "disp_channel",
            Hook::SensedForce => "force_channel",
        }
    }

    /// The hook called `key`.
    pub fn parse(key: &str) -> Option<Hook> {
        Self::ALL.into_iter().find(|h| h.key() == key)
    }

    /// The quantities its expression reads, in the order the hook gives them (`t` last).
    pub fn vars(self) -> &'static [&'static str] {
        match self {
            Hook::Force => &["y", "v", "t"],
            Hook::Flow1 | Hook::Flow2 => &["p1", "p2", "ps", "t"],
            Hook::Opening => &["x", "t"],
            Hook::Supply => &["ps", "t"],
            Hook::Accel | Hook::Disp | Hook::SensedForce => &["a", "d", "f", "t"],
        }
    }

    /// The unit of what it gives.
    pub fn unit(self) -> &'static str {
        match self {
            Hook::Force | Hook::SensedForce => "N",
            Hook::Flow1 | Hook::Flow2 => "m³/s",
            Hook::Opening | Hook::Disp => "m",
            Hook::Supply => "Pa",
            Hook::Accel => "m/s²",
        }
    }

    /// Whether it changes the hydraulics ([`Effect::HYDRAULIC`]).
    fn hydraulic(self) -> bool {
        matches!(
            self,
            Hook::Flow1 | Hook::Flow2 | Hook::Opening | Hook::Supply
        )
    }
}

/// One hook's expression: its source as written and its program.
#[derive(Debug, Clone)]
pub struct HookExpr {
    pub hook: Hook,
    pub source: String,
    pub program: Arc<Program>,
}

impl PartialEq for HookExpr {
    fn eq(&self, other: &Self) -> bool {
        (self.hook, &self.source) == (other.hook, &other.source)
    }
}

/// The expressions of a parameter set: the hooks given one, and the parameters' names by slot.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Expressions {
    pub hooks: Vec<HookExpr>,
    /// The name of each slot's parameter ("" where none is named).
    pub names: [String; SLOTS],
}

impl Expressions {
    /// Gives `hook` the expression `source` (replacing one it had), compiled against the slots'
    /// names.
    pub fn set(&mut self, hook: Hook, source: &str) -> Result<(), ExprError> {
        let names: Vec<&str> = self.names.iter().map(String::as_str).collect();
        let program = Arc::new(Program::compile(source, hook.vars(), &names)?);
        self.hooks.retain(|h| h.hook != hook);
        self.hooks.push(HookExpr {
            hook,
            source: source.to_string(),
            program,
        });
        Ok(())
    }

    /// The expression of `hook`, if it has one.
    pub fn get(&self, hook: Hook) -> Option<&HookExpr> {
        self.hooks.iter().find(|h| h.hook == hook)
    }

    /// The slots whose parameters some expression reads.
    pub fn slots_read(&self) -> Vec<usize> {
        let mut read: Vec<usize> = (self.hooks.iter())
            .flat_map(|h| h.program.params_read())
            .collect();
        read.sort_unstable();
        read.dedup();
        read
    }
}

pub struct Expression<const N: usize> {
    on: [f64; N],
    slots: [[f64; SLOTS]; N],
    /// The slots' values slot by slot, over the lanes (for [`Program::eval_lanes`]).
    by_slot: [[f64; N]; SLOTS],
    /// The force's program where every lane that switches the effect on has the same one (a
    /// diagnosis, a fit): evaluated over the lanes at once.
    shared_force: Option<Arc<Program>>,
    /// Each hook's program per lane (none where the lane has the effect off or no expression).
    programs: [[Option<Arc<Program>>; N]; Hook::ALL.len()],
    hydraulic: bool,
}

impl<const N: usize> LibraryEffect<N> for Expression<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        let programs = Hook::ALL.map(|hook| {
            std::array::from_fn(|l| {
                let e = p[l].expressions().get(hook).filter(|_| on[l] > 0.0);
                e.map(|e| Arc::clone(&e.program))
            })
        });
        let hydraulic = Hook::ALL
            .iter()
            .zip(&programs)
            .any(|(h, lanes)| h.hydraulic() && lanes.iter().any(Option::is_some));
        let slots = p.map(|m| Params::of(m).slots());
        let shared_force = shared(&programs[Hook::Force as usize], &on);
        Expression {
            on,
            slots,
            by_slot: std::array::from_fn(|k| std::array::from_fn(|l| slots[l][k])),
            shared_force,
            programs,
            hydraulic,
        }
    }
}

/// The program every lane that is on has (the same one, by address), if they share one.
fn shared<const N: usize>(
    lanes: &[Option<Arc<Program>>; N],
    on: &[f64; N],
) -> Option<Arc<Program>> {
    let mut on_lanes = (0..N).filter(|&l| on[l] > 0.0).map(|l| lanes[l].as_ref());
    let first = on_lanes.next()??;
    on_lanes
        .all(|p| p.is_some_and(|p| Arc::ptr_eq(p, first)))
        .then(|| Arc::clone(first))
}

impl<const N: usize> Expression<N> {
    /// `hook`'s expression in `lane` at the quantities `vars`, if the lane has one.
    #[inline(always)]
    fn run(&self, hook: Hook, lane: usize, vars: &[f64]) -> Option<f64> {
        let p = self.programs[hook as usize][lane].as_ref()?;
        Some(p.eval(vars, &self.slots[lane]))
    }
}

impl<const N: usize> Effect<N> for Expression<N> {
    /// The time since the start of the run, s (its derivative is 1 where the effect is on).
    type State = [[f64; N]; 1];

    fn initial_state(&self) -> Self::State {
        [[0.0; N]]
    }

    #[inline(always)]
    fn hydraulic(&self) -> bool {
        self.hydraulic
    }

    #[inline(always)]
    fn supply(&self, c: hook::Supply, s: &Self::State) -> f64 {
        let t = s[0][c.lane];
        self.run(Hook::Supply, c.lane, &[c.p_s, t]).unwrap_or(c.p_s)
    }

    #[inline(always)]
    fn opening(&self, c: hook::Opening, s: &Self::State) -> f64 {
        let t = s[0][c.lane];
        self.run(Hook::Opening, c.lane, &[c.x, t]).unwrap_or(c.x)
    }

    /// Net (into chamber 1, out of chamber 2): a flow into chamber 2 lessens what leaves it.
    #[inline(always)]
    fn flows(&self, c: hook::Flows, s: &Self::State) -> (f64, f64) {
        let vars = [c.p1, c.p2, c.p_s, s[0][c.lane]];
        let q1 = self.run(Hook::Flow1, c.lane, &vars).unwrap_or(0.0);
        let q2 = self.run(Hook::Flow2, c.lane, &vars).unwrap_or(0.0);
        (c.q.0 + q1, c.q.1 - q2)
    }

    #[inline(always)]
    fn extra_force(&self, c: hook::Motion, s: &Self::State) -> f64 {
        let t = s[0][c.lane];
        self.run(Hook::Force, c.lane, &[c.y, c.v, t]).unwrap_or(0.0)
    }

    /// Over the lanes at once where they share the program, lanes that are off giving 0.
    #[inline(always)]
    fn extra_forces(&self, y: &[f64; N], v: &[f64; N], s: &Self::State) -> [f64; N] {
        let Some(p) = &self.shared_force else {
            return std::array::from_fn(|lane| {
                let c = hook::Motion {
                    lane,
                    y: y[lane],
                    v: v[lane],
                };
                self.extra_force(c, s)
            });
        };
        let f = p.eval_lanes(&[y, v, &s[0]], &self.by_slot);
        std::array::from_fn(|l| if self.on[l] > 0.0 { f[l] } else { 0.0 })
    }

    #[inline(always)]
    fn derivs(&self, _plant: &PlantView<'_, N>, _s: &Self::State, ds: &mut Self::State) {
        ds[0] = self.on;
    }

    #[inline(always)]
    fn sensed(&self, c: hook::Sensed, s: &Self::State) -> [f64; 3] {
        let [a, d, f] = c.raw;
        let vars = [a, d, f, s[0][c.lane]];
        let channel = |hook, raw| self.run(hook, c.lane, &vars).unwrap_or(raw);
        [
            channel(Hook::Accel, a),
            channel(Hook::Disp, d),
            channel(Hook::SensedForce, f),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The slots a diagnosis frees are those some expression reads, each once, in order; a name
    /// that no expression reads is not among them.
    #[test]
    fn the_slots_read_are_those_some_expression_names() {
        let mut e = Expressions::default();
        assert!(e.slots_read().is_empty());
        e.names[0] = "k".into();
        e.names[2] = "c".into();
        e.names[3] = "unused".into();
        e.set(Hook::Force, "-c*v - k*y - c*sign(v)").unwrap();
        e.set(Hook::Flow1, "1e-12*c*(p1 - p2)").unwrap();
        assert_eq!(e.slots_read(), vec![0, 2]);
    }
}
