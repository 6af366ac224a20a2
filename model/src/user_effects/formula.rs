//! Formulas of user-defined effects: parsed here (so that a mistake is reported with its
//! position and an unknown name with the nearest known one), then compiled by `exmex`
//! into a flat expression evaluated once per right-hand side or output sample.
//!
//! Grammar, loosest first: `+ -`, `* /`, unary `-`, `^` (right-associative, binds tighter
//! than unary minus: `-x^2` is `-(x^2)`). Atoms: numbers (`12`, `0.5`, `1e-3`), names
//! (letters, digits, `_`, dotted parts as `armJoint.phi`), calls of the functions
//! [`FUNCTIONS`] and `pow(a, b)`, parentheses. `sign(0)` is 0 (and `sign(x)` ±1 elsewhere):
//! a term `c * sign(armJoint.w)` drives a joint at rest with nothing, as it reads in
//! mathematics, rather than with `c`.

use exmex::prelude::*;
use exmex::{FlatEx, FloatOpsFactory, MakeOperators, Operator};

/// Functions of one argument a formula may call (`pow(a, b)` takes two).
pub const FUNCTIONS: [&str; 7] = ["sin", "cos", "exp", "abs", "sign", "sqrt", "tanh"];

/// Most distinct names and numbers one formula may hold.
pub const MAX_SLOTS: usize = 64;

/// Longest formula accepted [characters], checked before anything reads it.
pub const MAX_LENGTH: usize = 10_000;

/// Deepest formula accepted: each parenthesis, call, sign and power nests one level, and so
/// does each operator chained at one level (`a + b + c` is two). Parsing, compiling and
/// dropping a formula recurse this deep, so it bounds their stack on any thread (a test
/// parses the deepest on a 512 KiB stack, a quarter of a tokio worker's).
pub const MAX_DEPTH: usize = 200;

/// A mistake in a formula: what, and the character (from 1) where it is.
#[derive(Debug, Clone, PartialEq)]
pub struct FormulaError {
    pub position: usize,
    pub message: String,
    /// The unknown name, when that is the mistake (for suggestions).
    pub unknown: Option<String>,
}

impl FormulaError {
    fn at(position: usize, message: impl Into<String>) -> Self {
        Self {
            position: position + 1,
            message: message.into(),
            unknown: None,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Node {
    Number(f64),
    Name(String, usize),
    Neg(Box<Node>),
    Binary(char, Box<Node>, Box<Node>),
    Call(String, Vec<Node>),
}

struct Parser<'a> {
    text: &'a str,
    bytes: &'a [u8],
    pos: usize,
    /// How many levels the parse is inside: every recursion enters one.
    depth: usize,
}

/// A parsed part and how deep its tree is.
struct Part {
    node: Node,
    depth: usize,
}

impl Part {
    fn leaf(node: Node) -> Self {
        Self { node, depth: 1 }
    }
}

impl Parser<'_> {
    /// Enter a level at the current character, refused beyond [`MAX_DEPTH`].
    fn enter(&mut self) -> Result<(), FormulaError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(FormulaError::at(self.pos, too_deep()));
        }
        Ok(())
    }

    /// `op` applied to `left` and `right`, refused when the tree grows beyond [`MAX_DEPTH`].
    fn binary(&self, op: u8, left: Part, right: Part, at: usize) -> Result<Part, FormulaError> {
        let depth = 1 + left.depth.max(right.depth);
        if depth > MAX_DEPTH {
            return Err(FormulaError::at(at, too_deep()));
        }
        Ok(Part {
            node: Node::Binary(op as char, Box::new(left.node), Box::new(right.node)),
            depth,
        })
    }

    fn skip(&mut self) {
        while self.pos < self.bytes.len() && self.bytes[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.skip();
        self.bytes.get(self.pos).copied()
    }

    fn expr(&mut self) -> Result<Part, FormulaError> {
        self.enter()?;
        let mut left = self.term()?;
        while let Some(op @ (b'+' | b'-')) = self.peek() {
            let at = self.pos;
            self.pos += 1;
            let right = self.term()?;
            left = self.binary(op, left, right, at)?;
        }
        self.depth -= 1;
        Ok(left)
    }

    fn term(&mut self) -> Result<Part, FormulaError> {
        let mut left = self.unary()?;
        while let Some(op @ (b'*' | b'/')) = self.peek() {
            let at = self.pos;
            self.pos += 1;
            let right = self.unary()?;
            left = self.binary(op, left, right, at)?;
        }
        Ok(left)
    }

    fn unary(&mut self) -> Result<Part, FormulaError> {
        match self.peek() {
            Some(sign @ (b'-' | b'+')) => {
                self.enter()?;
                self.pos += 1;
                let inner = self.unary()?;
                self.depth -= 1;
                if sign == b'+' {
                    return Ok(inner);
                }
                Ok(Part {
                    node: Node::Neg(Box::new(inner.node)),
                    depth: inner.depth + 1,
                })
            }
            _ => self.power(),
        }
    }

    fn power(&mut self) -> Result<Part, FormulaError> {
        let base = self.atom()?;
        if self.peek() == Some(b'^') {
            let at = self.pos;
            self.enter()?;
            self.pos += 1;
            let exponent = self.unary()?;
            self.depth -= 1;
            return self.binary(b'^', base, exponent, at);
        }
        Ok(base)
    }

    fn atom(&mut self) -> Result<Part, FormulaError> {
        let start = match self.peek() {
            None => return Err(FormulaError::at(self.pos, "the formula ends too early")),
            Some(_) => self.pos,
        };
        let c = self.bytes[start];
        if c == b'(' {
            self.pos += 1;
            let inner = self.expr()?;
            self.expect(b')', start)?;
            return Ok(inner);
        }
        if c.is_ascii_digit() || c == b'.' {
            return self.number().map(Part::leaf);
        }
        if c.is_ascii_alphabetic() || c == b'_' {
            let name = self.name();
            if self.peek() == Some(b'(') {
                return self.call(name, start);
            }
            return Ok(Part::leaf(Node::Name(name, start)));
        }
        let shown = self.text[start..].chars().next().unwrap_or(' ');
        Err(FormulaError::at(start, format!("unexpected `{shown}`")))
    }

    fn expect(&mut self, wanted: u8, opened: usize) -> Result<(), FormulaError> {
        if self.peek() == Some(wanted) {
            self.pos += 1;
            return Ok(());
        }
        let message = match self.peek() {
            None => format!("`(` at character {} is never closed", opened + 1),
            Some(_) => format!("expected `{}` here", wanted as char),
        };
        Err(FormulaError::at(self.pos, message))
    }

    fn name(&mut self) -> String {
        let start = self.pos;
        let part = |b: u8| b.is_ascii_alphanumeric() || b == b'_';
        while self.pos < self.bytes.len() {
            let b = self.bytes[self.pos];
            let dotted = b == b'.'
                && self
                    .bytes
                    .get(self.pos + 1)
                    .is_some_and(|n| n.is_ascii_alphabetic() || *n == b'_');
            if part(b) || dotted {
                self.pos += 1;
            } else {
                break;
            }
        }
        self.text[start..self.pos].to_string()
    }

    fn number(&mut self) -> Result<Node, FormulaError> {
        let start = self.pos;
        let digits = |p: &mut Self| {
            while p.pos < p.bytes.len() && p.bytes[p.pos].is_ascii_digit() {
                p.pos += 1;
            }
        };
        digits(self);
        if self.bytes.get(self.pos) == Some(&b'.') {
            self.pos += 1;
            digits(self);
        }
        if matches!(self.bytes.get(self.pos), Some(b'e' | b'E')) {
            let mark = self.pos;
            self.pos += 1;
            if matches!(self.bytes.get(self.pos), Some(b'+' | b'-')) {
                self.pos += 1;
            }
            let before = self.pos;
            digits(self);
            if self.pos == before {
                self.pos = mark;
            }
        }
        let text = &self.text[start..self.pos];
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(Node::Number(v)),
            _ => Err(FormulaError::at(start, format!("`{text}` is not a number"))),
        }
    }

    fn call(&mut self, name: String, start: usize) -> Result<Part, FormulaError> {
        let arity = match name.as_str() {
            "pow" => 2,
            n if FUNCTIONS.contains(&n) => 1,
            _ => {
                return Err(FormulaError {
                    unknown: Some(name.clone()),
                    ..FormulaError::at(start, format!("unknown function `{name}`"))
                })
            }
        };
        let open = self.pos;
        self.pos += 1;
        let mut args = vec![self.expr()?];
        while self.peek() == Some(b',') {
            self.pos += 1;
            args.push(self.expr()?);
        }
        self.expect(b')', open)?;
        if args.len() != arity {
            return Err(FormulaError::at(
                start,
                format!("`{name}` takes {arity} argument(s), not {}", args.len()),
            ));
        }
        // `pow(a, b)` is emitted as `a ^ b` under its call: two levels above its arguments.
        let levels = if name == "pow" { 2 } else { 1 };
        let depth = levels + args.iter().map(|a| a.depth).max().unwrap_or(0);
        if depth > MAX_DEPTH {
            return Err(FormulaError::at(start, too_deep()));
        }
        Ok(Part {
            node: Node::Call(name, args.into_iter().map(|a| a.node).collect()),
            depth,
        })
    }
}

fn too_deep() -> String {
    format!(
        "the formula nests more than {MAX_DEPTH} levels here (each parenthesis, call, sign \
         and power is a level, and so is each operator chained at one level)"
    )
}

/// The formula's tree: refused before reading when longer than [`MAX_LENGTH`], and as soon
/// as it nests deeper than [`MAX_DEPTH`].
fn parse(text: &str) -> Result<Node, FormulaError> {
    if text.len() > MAX_LENGTH {
        return Err(FormulaError::at(
            0,
            format!("{} characters, more than {MAX_LENGTH}", text.len()),
        ));
    }
    let mut p = Parser {
        text,
        bytes: text.as_bytes(),
        pos: 0,
        depth: 0,
    };
    if p.peek().is_none() {
        return Err(FormulaError::at(0, "the formula is empty"));
    }
    let node = p.expr()?.node;
    match p.peek() {
        None => Ok(node),
        Some(b')') => Err(FormulaError::at(p.pos, "`)` closes nothing")),
        Some(_) => Err(FormulaError::at(
            p.pos,
            "expected an operator (+ - * / ^) or the end here",
        )),
    }
}

/// Every name the formula reads, with the character position (from 0) where it first is.
/// Whether the formula `text` calls the function `function` (false when it does not parse).
pub fn calls(text: &str, function: &str) -> bool {
    fn walk(node: &Node, function: &str) -> bool {
        match node {
            Node::Number(_) | Node::Name(..) => false,
            Node::Neg(a) => walk(a, function),
            Node::Binary(_, a, b) => walk(a, function) || walk(b, function),
            Node::Call(f, args) => f == function || args.iter().any(|a| walk(a, function)),
        }
    }
    parse(text).is_ok_and(|node| walk(&node, function))
}

fn names(node: &Node, out: &mut Vec<(String, usize)>) {
    match node {
        Node::Number(_) => {}
        Node::Name(n, at) => {
            if !out.iter().any(|(m, _)| m == n) {
                out.push((n.clone(), *at));
            }
        }
        Node::Neg(a) => names(a, out),
        Node::Binary(_, a, b) => {
            names(a, out);
            names(b, out);
        }
        Node::Call(_, args) => args.iter().for_each(|a| names(a, out)),
    }
}

/// The formula in exmex's syntax, fully parenthesised: names in braces, numbers in plain
/// decimals (exact: Rust prints the shortest decimal that reads back to the same bits).
fn emit(node: &Node, out: &mut String) {
    match node {
        Node::Number(v) => out.push_str(&format!("({})", v)),
        Node::Name(n, _) => out.push_str(&format!("{{{n}}}")),
        Node::Neg(a) => {
            out.push_str("(-");
            emit(a, out);
            out.push(')');
        }
        Node::Binary(op, a, b) => {
            out.push('(');
            emit(a, out);
            out.push(*op);
            emit(b, out);
            out.push(')');
        }
        Node::Call(f, args) if f == "pow" => emit(
            &Node::Binary('^', Box::new(args[0].clone()), Box::new(args[1].clone())),
            out,
        ),
        Node::Call(f, args) => {
            let f = if f == "sign" { "sign0" } else { f.as_str() };
            out.push_str(&format!("({f}("));
            emit(&args[0], out);
            out.push_str("))");
        }
    }
}

/// The sign with `sign(0) = 0` (`f64::signum` gives ±1 at ±0).
fn sign(x: f64) -> f64 {
    if x == 0.0 {
        0.0
    } else {
        x.signum()
    }
}

/// exmex's operators for floats, and [`sign`] as `sign0` (what `sign` compiles to).
#[derive(Clone, Debug)]
struct Operators;

impl MakeOperators<f64> for Operators {
    fn make<'a>() -> Vec<Operator<'a, f64>> {
        let mut ops = FloatOpsFactory::<f64>::make();
        ops.push(Operator::make_unary("sign0", sign));
        ops
    }
}

/// A formula compiled, its names bound to slots of the caller's choosing.
#[derive(Clone, Debug)]
pub struct Compiled {
    expr: FlatEx<f64, Operators>,
    /// For each variable of `expr` (in its order), the index of the caller's name.
    slots: Vec<usize>,
}

impl Compiled {
    /// Parse `text` and compile it; every name it reads must be one of `known`.
    pub fn new(text: &str, known: &[String]) -> Result<Compiled, FormulaError> {
        let node = parse(text)?;
        let mut used = Vec::new();
        names(&node, &mut used);
        for (name, at) in &used {
            if !known.contains(name) {
                return Err(FormulaError {
                    unknown: Some(name.clone()),
                    ..FormulaError::at(*at, format!("unknown name `{name}`"))
                });
            }
        }
        if used.len() > MAX_SLOTS {
            return Err(FormulaError::at(
                0,
                format!("more than {MAX_SLOTS} distinct names"),
            ));
        }
        let mut source = String::new();
        emit(&node, &mut source);
        let expr = FlatEx::<f64, Operators>::parse(&source)
            .map_err(|e| FormulaError::at(0, format!("cannot compile: {e}")))?;
        let slots = expr
            .var_names()
            .iter()
            .map(|v| known.iter().position(|k| k == v).expect("checked above"))
            .collect();
        Ok(Compiled { expr, slots })
    }

    /// Indices (into the names it was compiled against) of the names it reads.
    pub fn reads(&self) -> &[usize] {
        &self.slots
    }

    /// Its value with name `k` worth `values[k]`.
    pub fn eval(&self, values: &[f64]) -> f64 {
        self.eval_by(|k| values[k])
    }

    /// Its value with name `k` worth `value(k)` (asked once per name it reads).
    #[inline]
    pub fn eval_by(&self, value: impl Fn(usize) -> f64) -> f64 {
        const SHORT: usize = 8;
        let n = self.slots.len();
        let result = if n <= SHORT {
            // Most formulas read a few names: their values on the stack.
            let mut args = [0.0; SHORT];
            for (a, &s) in args.iter_mut().zip(&self.slots) {
                *a = value(s);
            }
            self.expr.eval(&args[..n])
        } else {
            let args: Vec<f64> = self.slots.iter().map(|&s| value(s)).collect();
            self.expr.eval(&args)
        };
        result.unwrap_or(f64::NAN)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn known(names: &[&str]) -> Vec<String> {
        names.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn formulas_evaluate_as_written() {
        let k = known(&["a", "k", "armJoint.phi", "c", "x"]);
        let v = [0.013, 12.0, 0.7, 0.3, -2.0];
        let f = Compiled::new("a * sin(k * armJoint.phi + c)", &k).unwrap();
        assert_eq!(f.eval(&v), 0.013 * (12.0f64 * 0.7 + 0.3).sin());
        let f = Compiled::new("-x^2 + pow(x, 3) - 1e-3 / 2.5E2", &k).unwrap();
        assert_eq!(f.eval(&v), -4.0 + -8.0 - 1e-3 / 2.5e2);
        let f = Compiled::new("sign(x) * sqrt(abs(x)) + tanh(x) + exp(-a) + cos(c)", &k).unwrap();
        let x: f64 = -2.0;
        let want = x.signum() * x.abs().sqrt() + x.tanh() + (-0.013f64).exp() + 0.3f64.cos();
        assert_eq!(f.eval(&v), want);
    }

    #[test]
    fn the_sign_of_zero_is_zero() {
        let k = known(&["x"]);
        let f = Compiled::new("sign(x)", &k).unwrap();
        let values: Vec<f64> = [-3.0, -0.0, 0.0, 1e-300, 2.0]
            .iter()
            .map(|&x| f.eval(&[x]))
            .collect();
        assert_eq!(values, [-1.0, 0.0, 0.0, 1.0, 1.0]);
        assert!(f.eval(&[f64::NAN]).is_nan());
        assert!(calls("a * sign(x) + 1", "sign"));
        assert!(!calls("a * sin(x)", "sign") && !calls("sign(", "sign"));
    }

    #[test]
    fn mistakes_say_where_they_are() {
        let k = known(&["a", "armJoint.phi"]);
        let e = Compiled::new("a * sin(armJoint.ph)", &k).unwrap_err();
        assert_eq!((e.position, e.unknown.as_deref()), (9, Some("armJoint.ph")));
        let e = Compiled::new("a * (armJoint.phi + ", &k).unwrap_err();
        assert_eq!(e.position, 21, "{e:?}");
        let e = Compiled::new("a ** 2", &k).unwrap_err();
        assert_eq!((e.position, e.message.as_str()), (4, "unexpected `*`"));
        let e = Compiled::new("a + sinh(a)", &k).unwrap_err();
        assert_eq!(e.position, 5);
        assert!(e.message.contains("unknown function `sinh`"));
        let e = Compiled::new("a )", &k).unwrap_err();
        assert_eq!(e.position, 3);
    }

    /// `text` compiled against `known` on a thread with a 512 KiB stack, a quarter of a
    /// tokio worker's (or a rayon thread's): whatever the formula, an answer and never an
    /// overflow.
    fn on_a_small_stack(text: String, known: Vec<String>) -> Result<(), FormulaError> {
        std::thread::Builder::new()
            .stack_size(512 << 10)
            .spawn(move || {
                let compiled = Compiled::new(&text, &known);
                let called = calls(&text, "sign");
                compiled.map(|c| {
                    // Evaluating is flat: any depth, a value.
                    let _ = c.eval(&vec![0.5; known.len()]);
                    assert!(called || !text.contains("sign("));
                })
            })
            .expect("a thread")
            .join()
            .expect("parsing never overflows the stack")
    }

    fn repeat(open: &str, middle: &str, close: &str, n: usize) -> String {
        format!("{}{middle}{}", open.repeat(n), close.repeat(n))
    }

    #[test]
    fn the_deepest_formula_accepted_compiles_on_a_small_stack() {
        let k = known(&["x"]);
        let at_limit = [
            repeat("(", "x", ")", MAX_DEPTH - 1),
            repeat("-", "x", "", MAX_DEPTH - 1),
            repeat("sin(", "x", ")", MAX_DEPTH - 1),
            format!("x{}", "+x".repeat(MAX_DEPTH - 1)),
            format!("x{}", "^x".repeat(MAX_DEPTH - 1)),
            format!(
                "{}x{}",
                "pow(".repeat(MAX_DEPTH / 2 - 1),
                ",x)".repeat(MAX_DEPTH / 2 - 1)
            ),
        ];
        for text in at_limit {
            let shown = text[..40.min(text.len())].to_string();
            on_a_small_stack(text, k.clone()).unwrap_or_else(|e| panic!("{shown}…: {e:?}"));
        }
    }

    #[test]
    fn formulas_nested_beyond_the_limit_are_refused_where_they_go_too_deep() {
        let k = known(&["x"]);
        // The attacks: 2,000 nested parentheses (4 KB), 20,000 signs or powers, and a
        // 35,000-term sum (70 KB) refused by its length before it is read.
        let cases = [
            (repeat("(", "x", ")", 2_000), "nests more than"),
            (repeat("-", "x", "", 5_000), "nests more than"),
            (repeat("+", "x", "", 5_000), "nests more than"),
            (format!("x{}", "^x".repeat(4_000)), "nests more than"),
            (repeat("sin(", "x", ")", 1_000), "nests more than"),
            (format!("x{}", "+x".repeat(MAX_DEPTH)), "nests more than"),
            (format!("x{}", "+x".repeat(35_000)), "more than 10000"),
            (repeat("-", "x", "", 20_000), "more than 10000"),
        ];
        for (text, says) in cases {
            let shown = text[..20].to_string();
            let e = on_a_small_stack(text, k.clone()).unwrap_err();
            assert!(e.message.contains(says), "{shown}…: {e:?}");
            if says == "nests more than" {
                assert!(e.position > MAX_DEPTH / 2, "{shown}…: {e:?}");
            }
        }
        assert!(!calls(
            &format!("sign({})", repeat("(", "x", ")", 5_000)),
            "sign"
        ));
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]

        /// Any text, of any nesting and length, gets an answer: a formula or a mistake
        /// placed inside the text (or just past its end).
        #[test]
        fn any_text_is_compiled_or_refused_with_its_place(
            pieces in proptest::collection::vec(
                proptest::sample::select(vec![
                    "(", ")", "-", "+", "*", "/", "^", "x", "y", "1.5", "2e3", ",", "sin(",
                    "pow(", "sign(", " ", "(((((", ")))))", "-----", "^-x", "é", "1e999",
                ]),
                0..3_000,
            ),
            repeat_by in 1usize..8,
        ) {
            let text = pieces.concat().repeat(repeat_by);
            let len = text.chars().count();
            match on_a_small_stack(text, known(&["x", "y"])) {
                Ok(()) => {}
                Err(e) => proptest::prop_assert!(e.position >= 1 && e.position <= len + 1,
                    "{e:?} in {len} characters"),
            }
        }
    }
}
