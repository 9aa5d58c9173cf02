//! Arithmetic expressions of named quantities, compiled once into a small stack program and
//! evaluated in a step: the language of the `expression` effect (a force, a flow, an opening, a
//! supply pressure or a recorded channel written in a model file, no rebuild).
//!
//! The language: numbers (`4.2e5`), names (a hook's quantities, the effect's parameters, `pi`),
//! `+ - * / ^` (`^` binds tightest and to the right; `-x^2` is `-(x^2)`), parentheses, and the
//! functions of [`FUNCTIONS`]. Everything is `f64`; there are no comparisons or branches (`step`,
//! `sign`, `min`, `max` and `clamp` write what a branch would).
//!
//! ```
//! use vshake_kernel::expr::Program;
//! let p = Program::compile("-c * v * abs(v) + k*y^3", &["y", "v"], &["c", "k"]).unwrap();
//! assert_eq!(p.eval(&[0.5, -2.0], &[10.0, 4.0]), -10.0 * -2.0 * 2.0 + 4.0 * 0.125);
//! let e = Program::compile("c * vv", &["y", "v"], &["c"]).unwrap_err();
//! assert!(e.to_string().contains("unknown name `vv`"), "{e}");
//! ```

use std::fmt;

/// Most values a program keeps on its stack at once (a deeper expression is refused when it is
/// compiled, so that evaluation needs no allocation and no check).
pub const MAX_DEPTH: usize = 24;

/// The functions an expression may call, with their number of arguments.
pub const FUNCTIONS: [(&str, usize); 17] = [
    ("sin", 1),
    ("cos", 1),
    ("tan", 1),
    ("exp", 1),
    ("ln", 1),
    ("log10", 1),
    ("sqrt", 1),
    ("abs", 1),
    ("sign", 1),
    ("step", 1),
    ("tanh", 1),
    ("atan", 1),
    ("min", 2),
    ("max", 2),
    ("pow", 2),
    ("atan2", 2),
    ("clamp", 3),
];

/// One instruction of a [`Program`].
#[derive(Debug, Clone, Copy, PartialEq)]
enum Op {
    Const(f64),
    /// The hook's quantity at this index.
    Var(u8),
    /// The effect's parameter at this index.
    Param(u8),
    Neg,
    Add,
    Sub,
    Mul,
    Div,
    Pow,
    /// A function of [`FUNCTIONS`] of one argument, of two, and `clamp`, by index.
    Call1(u8),
    Call2(u8),
    Clamp,
    /// `x ^ n` for a whole constant n, 1 ≤ |n| ≤ 4: n − 1 products (and, for n < 0, one
    /// division), as the same power written as a product gives.
    PowInt(i8),
}

/// An expression compiled: a postfix program over a fixed-size stack.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    ops: Vec<Op>,
}

/// Why an expression does not compile: where (a character offset) and what.
#[derive(Debug, Clone, PartialEq)]
pub struct ExprError {
    /// Character offset in the source (0-based).
    pub at: usize,
    pub message: String,
}

impl fmt::Display for ExprError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "at character {}: {}", self.at + 1, self.message)
    }
}

impl std::error::Error for ExprError {}

impl Program {
    /// Compiles `src`, where `vars` are the hook's quantities (read by [`Program::eval`]'s `vars`
    /// in that order) and `params` the effect's parameters (likewise).
    pub fn compile(src: &str, vars: &[&str], params: &[&str]) -> Result<Program, ExprError> {
        let tokens = lex(src)?;
        let mut p = Parser {
            tokens: &tokens,
            pos: 0,
            vars,
            params,
            ops: Vec::new(),
            end: src.chars().count(),
        };
        p.expr()?;
        if let Some(t) = p.tokens.get(p.pos) {
            return Err(p.error_at(t.at, format!("unexpected {}", t.tok)));
        }
        let program = Program {
            ops: whole_powers(p.ops),
        };
        let depth = program.depth();
        if depth > MAX_DEPTH {
            return Err(ExprError {
                at: 0,
                message: format!("the expression needs a stack of {depth} (at most {MAX_DEPTH}): split it or simplify it"),
            });
        }
        Ok(program)
    }

    /// The stack depth the program reaches.
    fn depth(&self) -> usize {
        let (mut d, mut most) = (0usize, 0usize);
        for op in &self.ops {
            d = d + 1 - pops(*op);
            most = most.max(d);
        }
        most
    }

    /// The parameters (indices into `params` of [`Program::compile`]) the program reads.
    pub fn params_read(&self) -> Vec<usize> {
        let mut read: Vec<usize> = (self.ops.iter())
            .filter_map(|op| match op {
                Op::Param(i) => Some(*i as usize),
                _ => None,
            })
            .collect();
        read.sort_unstable();
        read.dedup();
        read
    }

    /// The value at quantities `vars` and parameters `params` (in [`Program::compile`]'s orders).
    #[inline]
    pub fn eval(&self, vars: &[f64], params: &[f64]) -> f64 {
        let mut st = Stack {
            v: [0.0; MAX_DEPTH],
            top: 0,
        };
        for op in &self.ops {
            match *op {
                Op::Const(c) => st.push(c),
                Op::Var(i) => st.push(vars[i as usize]),
                Op::Param(i) => st.push(params[i as usize]),
                Op::Neg => st.unary(|x| -x),
                Op::PowInt(n) => st.unary(|x| pow_int(x, n)),
                Op::Call1(f) => st.unary(|x| call1(f, x)),
                Op::Add => st.binary(|a, b| a + b),
                Op::Sub => st.binary(|a, b| a - b),
                Op::Mul => st.binary(|a, b| a * b),
                Op::Div => st.binary(|a, b| a / b),
                Op::Pow => st.binary(f64::powf),
                Op::Call2(f) => st.binary(|a, b| call2(f, a, b)),
                // clamp(x, lo, hi), without f64::clamp's panic where lo > hi or one is NaN.
                Op::Clamp => {
                    let hi = st.pop();
                    st.binary(|x, lo| x.max(lo).min(hi));
                }
            }
        }
        st.v[0]
    }
}

impl Program {
    /// [`Program::eval`] in every lane at once, the same operations in each lane (so the same
    /// bits): `vars[i]` and `params[j]` hold a quantity's and a parameter's value per lane. The
    /// interpretation is paid once for the N lanes; the arithmetic runs over the lanes.
    #[inline]
    pub fn eval_lanes<const N: usize>(&self, vars: &[&[f64; N]], params: &[[f64; N]]) -> [f64; N] {
        let mut st = [[0.0f64; N]; MAX_DEPTH];
        let mut top = 0usize;
        for op in &self.ops {
            let (below, at) = st.split_at_mut(top);
            match *op {
                Op::Const(c) => at[0] = [c; N],
                Op::Var(i) => at[0] = *vars[i as usize],
                Op::Param(i) => at[0] = params[i as usize],
                Op::Neg => lanes1(below, |x| -x),
                Op::PowInt(n) => lanes1(below, |x| pow_int(x, n)),
                Op::Call1(f) => lanes1(below, |x| call1(f, x)),
                Op::Add => lanes2(below, |a, b| a + b),
                Op::Sub => lanes2(below, |a, b| a - b),
                Op::Mul => lanes2(below, |a, b| a * b),
                Op::Div => lanes2(below, |a, b| a / b),
                Op::Pow => lanes2(below, f64::powf),
                Op::Call2(f) => lanes2(below, |a, b| call2(f, a, b)),
                Op::Clamp => {
                    let [.., x, lo, hi] = below else {
                        unreachable!("clamp reads three values")
                    };
                    (0..N).for_each(|l| x[l] = x[l].max(lo[l]).min(hi[l]));
                }
            }
            top = top + 1 - pops(*op);
        }
        st[0]
    }
}

/// The top of a lane stack `below` (the values under the next free slot) mapped by `f`.
#[inline(always)]
fn lanes1<const N: usize>(below: &mut [[f64; N]], f: impl Fn(f64) -> f64) {
    let x = below.last_mut().expect("a unary op reads one value");
    x.iter_mut().for_each(|x| *x = f(*x));
}

/// The two top values of a lane stack `below` combined by `f` into the lower one.
#[inline(always)]
fn lanes2<const N: usize>(below: &mut [[f64; N]], f: impl Fn(f64, f64) -> f64) {
    let [.., a, b] = below else {
        unreachable!("a binary op reads two values")
    };
    (0..N).for_each(|l| a[l] = f(a[l], b[l]));
}

/// A program's stack. Every program is postfix and reaches a depth of at most [`MAX_DEPTH`]
/// (checked by [`Program::compile`], which alone makes programs), so `top` stays in
/// 1..=MAX_DEPTH wherever a value is read and below MAX_DEPTH wherever one is pushed.
struct Stack {
    v: [f64; MAX_DEPTH],
    top: usize,
}

impl Stack {
    #[inline(always)]
    fn push(&mut self, x: f64) {
        debug_assert!(self.top < MAX_DEPTH);
        // SAFETY: top < MAX_DEPTH where a value is pushed (the type's invariant).
        unsafe { *self.v.get_unchecked_mut(self.top) = x };
        self.top += 1;
    }

    #[inline(always)]
    fn pop(&mut self) -> f64 {
        debug_assert!(self.top >= 1);
        self.top -= 1;
        // SAFETY: top was in 1..=MAX_DEPTH (the type's invariant).
        unsafe { *self.v.get_unchecked(self.top) }
    }

    #[inline(always)]
    fn unary(&mut self, f: impl Fn(f64) -> f64) {
        debug_assert!((1..=MAX_DEPTH).contains(&self.top));
        // SAFETY: top in 1..=MAX_DEPTH where a value is read (the type's invariant).
        let x = unsafe { self.v.get_unchecked_mut(self.top - 1) };
        *x = f(*x);
    }

    #[inline(always)]
    fn binary(&mut self, f: impl Fn(f64, f64) -> f64) {
        let b = self.pop();
        self.unary(|a| f(a, b));
    }
}

/// `ops` with each negated constant folded, and each `c ^` of a whole constant c, 1 ≤ |c| ≤ 4,
/// made a [`Op::PowInt`].
fn whole_powers(ops: Vec<Op>) -> Vec<Op> {
    let mut out: Vec<Op> = Vec::with_capacity(ops.len());
    for op in ops {
        match (op, out.last()) {
            (Op::Neg, Some(&Op::Const(c))) => {
                out.pop();
                out.push(Op::Const(-c));
            }
            (Op::Pow, Some(&Op::Const(c)))
                if c.fract() == 0.0 && (1.0..=4.0).contains(&c.abs()) =>
            {
                out.pop();
                out.push(Op::PowInt(c as i8));
            }
            _ => out.push(op),
        }
    }
    out
}

#[inline(always)]
fn pow_int(x: f64, n: i8) -> f64 {
    let m = n.unsigned_abs();
    let mut p = x;
    for _ in 1..m {
        p *= x;
    }
    if n < 0 {
        1.0 / p
    } else {
        p
    }
}

/// How many values an instruction takes off the stack (it puts one back).
fn pops(op: Op) -> usize {
    match op {
        Op::Const(_) | Op::Var(_) | Op::Param(_) => 0,
        Op::Neg | Op::PowInt(_) | Op::Call1(_) => 1,
        Op::Add | Op::Sub | Op::Mul | Op::Div | Op::Pow | Op::Call2(_) => 2,
        Op::Clamp => 3,
    }
}

#[inline(always)]
fn call1(f: u8, x: f64) -> f64 {
    match f {
        0 => x.sin(),
        1 => x.cos(),
        2 => x.tan(),
        3 => x.exp(),
        4 => x.ln(),
        5 => x.log10(),
        6 => x.sqrt(),
        7 => x.abs(),
        // sign(0) = 0 (f64::signum gives ±1 there).
        8 => (x > 0.0) as u8 as f64 - (x < 0.0) as u8 as f64,
        9 => (x >= 0.0) as u8 as f64,
        10 => x.tanh(),
        _ => x.atan(),
    }
}

#[inline(always)]
fn call2(f: u8, a: f64, b: f64) -> f64 {
    match f {
        12 => a.min(b),
        13 => a.max(b),
        14 => a.powf(b),
        _ => a.atan2(b),
    }
}

/// A token of the source, with its character offset.
#[derive(Debug, Clone, PartialEq)]
struct Token {
    tok: Tok,
    at: usize,
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Name(String),
    Sym(char),
}

impl fmt::Display for Tok {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Tok::Num(v) => write!(f, "number {v}"),
            Tok::Name(n) => write!(f, "name `{n}`"),
            Tok::Sym(c) => write!(f, "`{c}`"),
        }
    }
}

fn lex(src: &str) -> Result<Vec<Token>, ExprError> {
    let chars: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if c.is_whitespace() {
            i += 1;
        } else if c.is_ascii_digit() || c == '.' {
            let (v, next) = number(&chars, i)?;
            out.push(Token {
                tok: Tok::Num(v),
                at: i,
            });
            i = next;
        } else if c.is_alphabetic() || c == '_' {
            let start = i;
            while i < chars.len() && (chars[i].is_alphanumeric() || chars[i] == '_') {
                i += 1;
            }
            let name: String = chars[start..i].iter().collect();
            out.push(Token {
                tok: Tok::Name(name),
                at: start,
            });
        } else if "+-*/^(),".contains(c) {
            out.push(Token {
                tok: Tok::Sym(c),
                at: i,
            });
            i += 1;
        } else {
            return Err(ExprError {
                at: i,
                message: format!("unexpected character {c:?}"),
            });
        }
    }
    Ok(out)
}

/// The number starting at `chars[i]` (digits, a point, an exponent), and where it ends.
fn number(chars: &[char], start: usize) -> Result<(f64, usize), ExprError> {
    let mut i = start;
    let digits = |i: &mut usize| {
        while *i < chars.len() && (chars[*i].is_ascii_digit() || chars[*i] == '.') {
            *i += 1;
        }
    };
    digits(&mut i);
    if i < chars.len() && (chars[i] == 'e' || chars[i] == 'E') {
        let mut j = i + 1;
        if j < chars.len() && (chars[j] == '+' || chars[j] == '-') {
            j += 1;
        }
        if j < chars.len() && chars[j].is_ascii_digit() {
            i = j;
            digits(&mut i);
        }
    }
    let text: String = chars[start..i].iter().collect();
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok((v, i)),
        Ok(_) => Err(ExprError {
            at: start,
            message: format!("{text} is too large for a 64-bit float"),
        }),
        Err(_) => Err(ExprError {
            at: start,
            message: format!("{text:?} is not a number"),
        }),
    }
}

/// Recursive descent, emitting postfix: expr = term {(+|-) term}; term = unary {(*|/) unary};
/// unary = - unary | power; power = atom [^ unary]; atom = number | name | name(args) | (expr).
struct Parser<'a> {
    tokens: &'a [Token],
    pos: usize,
    vars: &'a [&'a str],
    params: &'a [&'a str],
    ops: Vec<Op>,
    /// The source's length in characters (where "the end" is).
    end: usize,
}

impl Parser<'_> {
    fn error_at(&self, at: usize, message: String) -> ExprError {
        ExprError { at, message }
    }

    fn peek_sym(&self) -> Option<char> {
        match self.tokens.get(self.pos) {
            Some(Token {
                tok: Tok::Sym(c), ..
            }) => Some(*c),
            _ => None,
        }
    }

    fn expect(&mut self, c: char) -> Result<(), ExprError> {
        if self.peek_sym() == Some(c) {
            self.pos += 1;
            return Ok(());
        }
        Err(match self.tokens.get(self.pos) {
            Some(t) => self.error_at(t.at, format!("expected `{c}`, found {}", t.tok)),
            None => self.error_at(self.end, format!("expected `{c}` before the end")),
        })
    }

    fn expr(&mut self) -> Result<(), ExprError> {
        self.term()?;
        while let Some(c @ ('+' | '-')) = self.peek_sym() {
            self.pos += 1;
            self.term()?;
            self.ops.push(if c == '+' { Op::Add } else { Op::Sub });
        }
        Ok(())
    }

    fn term(&mut self) -> Result<(), ExprError> {
        self.unary()?;
        while let Some(c @ ('*' | '/')) = self.peek_sym() {
            self.pos += 1;
            self.unary()?;
            self.ops.push(if c == '*' { Op::Mul } else { Op::Div });
        }
        Ok(())
    }

    fn unary(&mut self) -> Result<(), ExprError> {
        match self.peek_sym() {
            Some('-') => {
                self.pos += 1;
                self.unary()?;
                self.ops.push(Op::Neg);
                Ok(())
            }
            Some('+') => {
                self.pos += 1;
                self.unary()
            }
            _ => self.power(),
        }
    }

    fn power(&mut self) -> Result<(), ExprError> {
        self.atom()?;
        if self.peek_sym() == Some('^') {
            self.pos += 1;
            self.unary()?;
            self.ops.push(Op::Pow);
        }
        Ok(())
    }

    fn atom(&mut self) -> Result<(), ExprError> {
        let Some(t) = self.tokens.get(self.pos).cloned() else {
            return Err(self.error_at(self.end, "the expression ends too early".into()));
        };
        self.pos += 1;
        match t.tok {
            Tok::Num(v) => self.ops.push(Op::Const(v)),
            Tok::Sym('(') => {
                self.expr()?;
                self.expect(')')?;
            }
            Tok::Name(name) if self.peek_sym() == Some('(') => self.call(&name, t.at)?,
            Tok::Name(name) => self.name(&name, t.at)?,
            other => return Err(self.error_at(t.at, format!("unexpected {other}"))),
        }
        Ok(())
    }

    fn name(&mut self, name: &str, at: usize) -> Result<(), ExprError> {
        let op = if let Some(i) = self.vars.iter().position(|v| *v == name) {
            Op::Var(i as u8)
        } else if let Some(i) = self.params.iter().position(|p| *p == name) {
            Op::Param(i as u8)
        } else if name == "pi" {
            Op::Const(std::f64::consts::PI)
        } else {
            let names = [self.vars, self.params].concat();
            let known: Vec<&str> = names.into_iter().filter(|n| !n.is_empty()).collect();
            let known = known.join(", ");
            return Err(self.error_at(
                at,
                format!("unknown name `{name}` (this expression knows {known} and pi)"),
            ));
        };
        self.ops.push(op);
        Ok(())
    }

    fn call(&mut self, name: &str, at: usize) -> Result<(), ExprError> {
        let Some(f) = FUNCTIONS.iter().position(|(n, _)| *n == name) else {
            let known: Vec<&str> = FUNCTIONS.iter().map(|(n, _)| *n).collect();
            return Err(self.error_at(
                at,
                format!(
                    "unknown function `{name}` (the functions: {})",
                    known.join(", ")
                ),
            ));
        };
        self.expect('(')?;
        let arity = FUNCTIONS[f].1;
        let takes = |e: ExprError| ExprError {
            message: format!("{name} takes {arity} argument(s): {}", e.message),
            ..e
        };
        for k in 0..arity {
            if k > 0 {
                self.expect(',').map_err(takes)?;
            }
            self.expr()?;
        }
        self.expect(')').map_err(takes)?;
        self.ops.push(match arity {
            1 => Op::Call1(f as u8),
            2 => Op::Call2(f as u8),
            _ => Op::Clamp,
        });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eval(src: &str, vars: &[(&str, f64)]) -> f64 {
        let names: Vec<&str> = vars.iter().map(|v| v.0).collect();
        let values: Vec<f64> = vars.iter().map(|v| v.1).collect();
        Program::compile(src, &names, &[])
            .unwrap()
            .eval(&values, &[])
    }

    #[test]
    fn precedence_and_associativity_are_the_usual_ones() {
        assert_eq!(eval("1 + 2 * 3", &[]), 7.0);
        assert_eq!(eval("(1 + 2) * 3", &[]), 9.0);
        assert_eq!(eval("2 ^ 3 ^ 2", &[]), 512.0);
        // Whole powers are products: x^3 is x·x·x, x^-2 is 1/(x·x), bit for bit.
        let x = 1.1f64;
        assert_eq!(eval("x^3", &[("x", x)]).to_bits(), (x * x * x).to_bits());
        assert_eq!(
            eval("x^-2", &[("x", x)]).to_bits(),
            (1.0 / (x * x)).to_bits()
        );
        assert_eq!(eval("x^0.5", &[("x", x)]), x.powf(0.5));
        assert_eq!(eval("-x^2", &[("x", 3.0)]), -9.0);
        assert_eq!(eval("8 / 4 / 2", &[]), 1.0);
        assert_eq!(eval("10 - 4 - 3", &[]), 3.0);
        assert_eq!(eval("2 * -x", &[("x", 3.0)]), -6.0);
        assert_eq!(eval("1.5e3 + .5 + 2E-1", &[]), 1500.7);
    }

    #[test]
    fn functions_give_the_library_s_values() {
        let x: f64 = 0.37;
        for (src, want) in [
            ("sin(x)", x.sin()),
            ("exp(x) * ln(x)", x.exp() * x.ln()),
            ("tanh(x/0.1)", (x / 0.1).tanh()),
            (
                "sign(-x) + sign(0) + step(0) + step(-x)",
                -1.0 + 0.0 + 1.0 + 0.0,
            ),
            ("min(x, 0.2) + max(x, 0.2)", 0.2 + x),
            ("clamp(x, 0.4, 1) + clamp(-x, -0.1, 0.1)", 0.4 - 0.1),
            (
                "pow(x, 2.5) - x^2.5 + atan2(x, 1) + sqrt(x)",
                x.atan2(1.0) + x.sqrt(),
            ),
            ("2*pi", 2.0 * std::f64::consts::PI),
        ] {
            assert_eq!(eval(src, &[("x", x)]), want, "{src}");
        }
    }

    #[test]
    fn parameters_are_read_by_index() {
        let p = Program::compile("k * y + c", &["y"], &["c", "k"]).unwrap();
        assert_eq!(p.eval(&[2.0], &[1.0, 10.0]), 21.0);
        assert_eq!(p.params_read(), vec![0, 1]);
    }

    /// Over the lanes, each lane's value is the one-lane evaluation's, bit for bit.
    #[test]
    fn the_lanes_give_each_lane_s_bits() {
        let src =
            "-tanh(y / k) * (c + (k - c) * exp(-(y / 0.3)^2)) + clamp(y, -c, c) + min(y, k)^1.5";
        let p = Program::compile(src, &["y"], &["c", "k"]).unwrap();
        let y: [f64; 4] = [0.1, -0.7, 2.5, 0.0];
        let (c, k) = ([0.2, 0.4, 1.0, 3.0], [1.5, 0.9, 0.3, 2.0]);
        let all = p.eval_lanes(&[&y], &[c, k]);
        for l in 0..4 {
            let one = p.eval(&[y[l]], &[c[l], k[l]]);
            assert_eq!(
                all[l].to_bits(),
                one.to_bits(),
                "lane {l}: {} {one}",
                all[l]
            );
        }
    }

    #[test]
    fn errors_say_where_and_what() {
        let err = |src: &str| Program::compile(src, &["y", "v"], &["k"]).unwrap_err();
        let e = err("k * yy");
        assert_eq!(e.at, 4);
        assert!(
            e.message.contains("unknown name `yy`") && e.message.contains("y, v, k"),
            "{e}"
        );
        assert!(err("sinh(y)").message.contains("unknown function `sinh`"));
        assert!(
            err("min(y)").message.contains("min takes 2 argument(s)"),
            "{}",
            err("min(y)")
        );
        assert!(err("(y + v").message.contains("expected `)`"));
        assert!(err("y +").message.contains("ends too early"));
        assert!(err("y v").message.contains("unexpected name `v`"));
        assert!(err("y # 2").message.contains("unexpected character '#'"));
        assert!(err("1.2.3").message.contains("not a number"));
        assert!(
            err("1e400 * y").message.contains("too large"),
            "{}",
            err("1e400 * y")
        );
        let deep = format!("{}y{}", "(y+".repeat(30), ")".repeat(30));
        assert!(err(&deep).message.contains("stack of"), "{}", err(&deep));
    }
}
