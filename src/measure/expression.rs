//! Arithmetic expressions over named symbols, evaluated with their gradient by forward-mode dual
//! numbers: what a model file's declared effects (`effects/declared.rs`) are written in.
//!
//! Grammar: numbers (`2`, `1.5e-3`), symbols (`age`, `a`, `material.yield_stress`: letters,
//! digits, `_` and `.`, not starting with a digit), `+ - * /`, `^` (right-associative, above unary
//! minus: `-a^2` is `-(a^2)`), parentheses, and the functions `exp`, `ln` (`log`), `log10`,
//! `sqrt`, `abs`, `sin`, `cos`, `tanh`.
//!
//! The derivative comes from the expression itself, so an effect written in a model file needs no
//! adjoint of its own. `x^y` takes the limits where a formula would give 0 * infinity: d(x^y)/dy =
//! x^y ln x is 0 where x^y = 0 (an experiment at age 0 under `age^b`), and a constant exponent
//! contributes no ln x term at all, so `(-2)^2` differentiates in x.

use super::error::MeasureError;

/// A parsed expression.
#[derive(Clone, Debug, PartialEq)]
pub struct Expression {
    text: String,
    root: Node,
    symbols: Vec<String>,
}

#[derive(Clone, Debug, PartialEq)]
enum Node {
    Number(f64),
    /// Index into the symbols.
    Symbol(usize),
    Neg(Box<Node>),
    Binary(Op, Box<Node>, Box<Node>),
    Call(Function, Box<Node>),
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Op {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Function {
    Exp,
    Ln,
    Log10,
    Sqrt,
    Abs,
    Sin,
    Cos,
    Tanh,
}

const FUNCTIONS: &[(&str, Function)] = &[
    ("exp", Function::Exp),
    ("ln", Function::Ln),
    ("log", Function::Ln),
    ("log10", Function::Log10),
    ("sqrt", Function::Sqrt),
    ("abs", Function::Abs),
    ("sin", Function::Sin),
    ("cos", Function::Cos),
    ("tanh", Function::Tanh),
];

#[derive(Clone, Debug, PartialEq)]
enum Token {
    Number(f64),
    Name(String),
    Op(char),
    Open,
    Close,
}

fn tokens(text: &str) -> Result<Vec<(Token, usize)>, MeasureError> {
    let chars: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let start = i;
        if c.is_whitespace() {
            i += 1;
            continue;
        }
        if c.is_ascii_digit() || (c == '.' && chars.get(i + 1).is_some_and(|d| d.is_ascii_digit())) {
            while i < chars.len() && (chars[i].is_ascii_digit() || chars[i] == '.') {
                i += 1;
            }
            // an exponent: e or E, an optional sign, digits
            if i < chars.len() && (chars[i] == 'e' || chars[i] == 'E') {
                let mut j = i + 1;
                if j < chars.len() && (chars[j] == '+' || chars[j] == '-') {
                    j += 1;
                }
                if j < chars.len() && chars[j].is_ascii_digit() {
                    i = j;
                    while i < chars.len() && chars[i].is_ascii_digit() {
                        i += 1;
                    }
                }
            }
            let s: String = chars[start..i].iter().collect();
            let v = s
                .parse::<f64>()
                .map_err(|_| MeasureError::Expression(format!("'{s}' is not a number (at character {})", start + 1)))?;
            out.push((Token::Number(v), start));
        } else if c.is_alphabetic() || c == '_' {
            while i < chars.len() && (chars[i].is_alphanumeric() || chars[i] == '_' || chars[i] == '.') {
                i += 1;
            }
            out.push((Token::Name(chars[start..i].iter().collect()), start));
        } else {
            let t = match c {
                '+' | '-' | '*' | '/' | '^' => Token::Op(c),
                '(' => Token::Open,
                ')' => Token::Close,
                _ => return Err(MeasureError::Expression(format!("unexpected '{c}' at character {}", i + 1))),
            };
            out.push((t, start));
            i += 1;
        }
    }
    Ok(out)
}

/// The deepest an expression may nest (parentheses, calls, signs and exponents, each a level):
/// the parser, the evaluation and the tree's drop recurse once per level, and 10,000 levels
/// overflow the stack. A physical law needs a handful.
pub const MAX_DEPTH: usize = 64;

struct Parser {
    tokens: Vec<(Token, usize)>,
    at: usize,
    symbols: Vec<String>,
    /// The levels `unary` is nested in now: every nesting passes through it.
    depth: usize,
}

impl Parser {
    fn peek(&self) -> Option<&Token> {
        self.tokens.get(self.at).map(|(t, _)| t)
    }

    fn where_(&self) -> String {
        match self.tokens.get(self.at) {
            Some((_, p)) => format!("at character {}", p + 1),
            None => "at the end".to_string(),
        }
    }

    /// sum := product (('+' | '-') product)*
    fn sum(&mut self) -> Result<Node, MeasureError> {
        let mut left = self.product()?;
        while let Some(Token::Op(c @ ('+' | '-'))) = self.peek().cloned() {
            self.at += 1;
            let right = self.product()?;
            left = Node::Binary(if c == '+' { Op::Add } else { Op::Sub }, Box::new(left), Box::new(right));
        }
        Ok(left)
    }

    /// product := unary (('*' | '/') unary)*
    fn product(&mut self) -> Result<Node, MeasureError> {
        let mut left = self.unary()?;
        while let Some(Token::Op(c @ ('*' | '/'))) = self.peek().cloned() {
            self.at += 1;
            let right = self.unary()?;
            left = Node::Binary(if c == '*' { Op::Mul } else { Op::Div }, Box::new(left), Box::new(right));
        }
        Ok(left)
    }

    /// unary := ('-' | '+') unary | power, at most [`MAX_DEPTH`] levels deep.
    fn unary(&mut self) -> Result<Node, MeasureError> {
        if self.depth == MAX_DEPTH {
            return Err(MeasureError::Expression(format!(
                "the expression nests deeper than {MAX_DEPTH} levels (parentheses, calls, signs, exponents) {}",
                self.where_()
            )));
        }
        self.depth += 1;
        let node = self.unary_level();
        self.depth -= 1;
        node
    }

    fn unary_level(&mut self) -> Result<Node, MeasureError> {
        match self.peek() {
            Some(Token::Op('-')) => {
                self.at += 1;
                Ok(Node::Neg(Box::new(self.unary()?)))
            }
            Some(Token::Op('+')) => {
                self.at += 1;
                self.unary()
            }
            _ => self.power(),
        }
    }

    /// power := atom ('^' unary)?   (right-associative: a^b^c = a^(b^c); a^-b allowed)
    fn power(&mut self) -> Result<Node, MeasureError> {
        let base = self.atom()?;
        if let Some(Token::Op('^')) = self.peek() {
            self.at += 1;
            let exponent = self.unary()?;
            return Ok(Node::Binary(Op::Pow, Box::new(base), Box::new(exponent)));
        }
        Ok(base)
    }

    fn atom(&mut self) -> Result<Node, MeasureError> {
        let here = self.where_();
        match self.tokens.get(self.at).map(|(t, _)| t.clone()) {
            Some(Token::Number(v)) => {
                self.at += 1;
                Ok(Node::Number(v))
            }
            Some(Token::Name(name)) => {
                self.at += 1;
                if let Some(Token::Open) = self.peek() {
                    let f = FUNCTIONS.iter().find(|(n, _)| *n == name).map(|(_, f)| *f).ok_or_else(|| {
                        MeasureError::Expression(format!(
                            "unknown function '{name}' {here}; known: {}",
                            FUNCTIONS.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
                        ))
                    })?;
                    self.at += 1;
                    let arg = self.sum()?;
                    self.close()?;
                    return Ok(Node::Call(f, Box::new(arg)));
                }
                let i = match self.symbols.iter().position(|s| *s == name) {
                    Some(i) => i,
                    None => {
                        self.symbols.push(name);
                        self.symbols.len() - 1
                    }
                };
                Ok(Node::Symbol(i))
            }
            Some(Token::Open) => {
                self.at += 1;
                let inner = self.sum()?;
                self.close()?;
                Ok(inner)
            }
            Some(t) => Err(MeasureError::Expression(format!(
                "expected a number, a name or '(' {here}, found {}",
                describe(&t)
            ))),
            None => {
                Err(MeasureError::Expression("the expression ends where a number, a name or '(' should be".to_string()))
            }
        }
    }

    fn close(&mut self) -> Result<(), MeasureError> {
        match self.peek() {
            Some(Token::Close) => {
                self.at += 1;
                Ok(())
            }
            _ => Err(MeasureError::Expression(format!("expected ')' {}", self.where_()))),
        }
    }
}

fn describe(t: &Token) -> String {
    match t {
        Token::Number(v) => format!("the number {v}"),
        Token::Name(n) => format!("'{n}'"),
        Token::Op(c) => format!("'{c}'"),
        Token::Open => "'('".into(),
        Token::Close => "')'".into(),
    }
}

/// A value and its derivatives in each symbol.
#[derive(Clone, Debug)]
struct Dual {
    v: f64,
    d: Vec<f64>,
}

impl Dual {
    fn constant(v: f64, n: usize) -> Dual {
        Dual { v, d: vec![0.0; n] }
    }
    /// v and d(v) = a d(x) + b d(y)
    fn combine(v: f64, x: &Dual, a: f64, y: &Dual, b: f64) -> Dual {
        Dual { v, d: x.d.iter().zip(&y.d).map(|(dx, dy)| chain(a, *dx) + chain(b, *dy)).collect() }
    }
    fn scaled(v: f64, x: &Dual, a: f64) -> Dual {
        Dual { v, d: x.d.iter().map(|dx| chain(a, *dx)).collect() }
    }
}

/// a * dx where a symbol that does not move (dx = 0) contributes 0 even through an infinite or
/// undefined partial (the exponent's ln x at x = 0, a root's slope at 0).
fn chain(a: f64, dx: f64) -> f64 {
    if dx == 0.0 {
        0.0
    } else {
        a * dx
    }
}

impl Expression {
    pub fn parse(text: &str) -> Result<Expression, MeasureError> {
        let tokens = tokens(text)?;
        if tokens.is_empty() {
            return Err(MeasureError::Expression("the expression is empty".into()));
        }
        let mut p = Parser { tokens, at: 0, symbols: Vec::new(), depth: 0 };
        let root = p.sum()?;
        if p.at < p.tokens.len() {
            let t = p.tokens[p.at].0.clone();
            return Err(MeasureError::Expression(format!("unexpected {} {}", describe(&t), p.where_())));
        }
        Ok(Expression { text: text.to_string(), root, symbols: p.symbols })
    }

    pub fn text(&self) -> &str {
        &self.text
    }

    /// The symbols it reads, in order of first appearance: `values` follow this order.
    pub fn symbols(&self) -> &[String] {
        &self.symbols
    }

    pub fn eval(&self, values: &[f64]) -> f64 {
        self.eval_grad(values).0
    }

    /// The value and its derivative in each symbol.
    pub fn eval_grad(&self, values: &[f64]) -> (f64, Vec<f64>) {
        assert_eq!(values.len(), self.symbols.len(), "one value per symbol");
        let d = eval(&self.root, values);
        (d.v, d.d)
    }
}

fn eval(node: &Node, x: &[f64]) -> Dual {
    let n = x.len();
    match node {
        Node::Number(v) => Dual::constant(*v, n),
        Node::Symbol(i) => {
            let mut d = Dual::constant(x[*i], n);
            d.d[*i] = 1.0;
            d
        }
        Node::Neg(a) => {
            let a = eval(a, x);
            Dual::scaled(-a.v, &a, -1.0)
        }
        Node::Binary(op, a, b) => {
            let (a, b) = (eval(a, x), eval(b, x));
            match op {
                Op::Add => Dual::combine(a.v + b.v, &a, 1.0, &b, 1.0),
                Op::Sub => Dual::combine(a.v - b.v, &a, 1.0, &b, -1.0),
                Op::Mul => Dual::combine(a.v * b.v, &a, b.v, &b, a.v),
                Op::Div => Dual::combine(a.v / b.v, &a, 1.0 / b.v, &b, -a.v / (b.v * b.v)),
                Op::Pow => {
                    let v = a.v.powf(b.v);
                    // d(x^y) = y x^(y-1) dx + x^y ln x dy; x^y ln x -> 0 as x^y -> 0
                    let dx = if b.v == 0.0 { 0.0 } else { b.v * a.v.powf(b.v - 1.0) };
                    let dy = if v == 0.0 { 0.0 } else { v * a.v.ln() };
                    Dual::combine(v, &a, dx, &b, dy)
                }
            }
        }
        Node::Call(f, a) => {
            let a = eval(a, x);
            let (v, slope) = match f {
                Function::Exp => {
                    let e = a.v.exp();
                    (e, e)
                }
                Function::Ln => (a.v.ln(), 1.0 / a.v),
                Function::Log10 => (a.v.log10(), 1.0 / (a.v * std::f64::consts::LN_10)),
                Function::Sqrt => {
                    let s = a.v.sqrt();
                    (s, 0.5 / s)
                }
                Function::Abs => (a.v.abs(), if a.v < 0.0 { -1.0 } else { 1.0 }),
                Function::Sin => (a.v.sin(), a.v.cos()),
                Function::Cos => (a.v.cos(), -a.v.sin()),
                Function::Tanh => {
                    let t = a.v.tanh();
                    (t, 1.0 - t * t)
                }
            };
            Dual::scaled(v, &a, slope)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 53 finding 1: 10,000 nested parentheses (or signs, or exponents) overflowed the
    /// stack; past MAX_DEPTH they are an error saying so, and a law as deep as the limit parses.
    #[test]
    fn an_expression_nested_too_deep_is_an_error_not_a_stack_overflow() {
        let n = 10_000;
        for text in [
            format!("{}x{}", "(".repeat(n), ")".repeat(n)),
            format!("{}x", "-".repeat(n)),
            format!("x{}", "^x".repeat(n)),
            format!("{}x{}", "exp(".repeat(n), ")".repeat(n)),
        ] {
            let e = Expression::parse(&text).unwrap_err().to_string();
            assert!(e.contains(&format!("nests deeper than {MAX_DEPTH} levels")), "{e}");
        }
        let deep = format!("{}x{}", "(".repeat(MAX_DEPTH - 1), ")".repeat(MAX_DEPTH - 1));
        assert_eq!(Expression::parse(&deep).unwrap().eval(&[2.5]), 2.5);
    }

    /// Every derivative against central differences, at a point where each symbol matters.
    #[test]
    fn derivatives_agree_with_central_differences() {
        for (text, at) in [
            ("tau * (1 + a * age^b)", vec![100.0, 2e-3, 1800.0, 0.7]),
            ("-x^2 / (1 + y) - 3e-1 * x", vec![1.3, 0.4]),
            (
                "exp(-t / s) * sqrt(u) + ln(u) - log10(u) + tanh(v) * sin(v) + cos(v) * abs(w)",
                vec![2.0, 5.0, 3.0, 0.3, -1.5],
            ),
            ("x ^ y ^ z", vec![1.2, 1.1, 0.9]),
            ("material.viscosity * exp(-e * (temperature - 20))", vec![20.0, 0.02, 35.0]),
        ] {
            let e = Expression::parse(text).unwrap();
            assert_eq!(e.symbols().len(), at.len(), "{text}: {:?}", e.symbols());
            let (_, g) = e.eval_grad(&at);
            for i in 0..at.len() {
                let h = 1e-6 * at[i].abs().max(1e-3);
                let (mut p, mut m) = (at.clone(), at.clone());
                p[i] += h;
                m[i] -= h;
                let fd = (e.eval(&p) - e.eval(&m)) / (2.0 * h);
                assert!(
                    (g[i] - fd).abs() <= 1e-6 * fd.abs().max(1e-6),
                    "{text}: d/d{}: {} vs {fd}",
                    e.symbols()[i],
                    g[i]
                );
            }
        }
    }

    #[test]
    fn precedence_and_values() {
        let v = |t: &str, x: &[f64]| Expression::parse(t).unwrap().eval(x);
        assert_eq!(v("1 + 2 * 3", &[]), 7.0);
        assert_eq!(v("-2^2", &[]), -4.0);
        assert_eq!(v("2^3^2", &[]), 512.0);
        assert_eq!(v("2^-1", &[]), 0.5);
        assert_eq!(v("(1 + 2) * 3 / 4 - 1", &[]), 1.25);
        assert_eq!(v("1.5e-3 * 2E2", &[]), 0.3);
        assert_eq!(v("a - b - c", &[10.0, 3.0, 2.0]), 5.0);
        assert_eq!(Expression::parse("b * a + b").unwrap().symbols(), ["b", "a"]);
    }

    /// Where a formula would give 0 * infinity the limit is taken: age^b at age 0.
    #[test]
    fn a_power_at_zero_has_finite_derivatives() {
        let e = Expression::parse("tau * (1 + a * age^b)").unwrap();
        let (v, g) = e.eval_grad(&[100.0, 2e-3, 0.0, 0.7]);
        assert_eq!(v, 100.0);
        // in tau, a and b (the slope in age itself is infinite there, as it is)
        assert_eq!([g[0], g[1], g[3]], [1.0, 0.0, 0.0], "{g:?}");
        // a constant exponent of a negative base
        let (v, g) = Expression::parse("x^2").unwrap().eval_grad(&[-2.0]);
        assert_eq!((v, g[0]), (4.0, -4.0));
    }

    #[test]
    fn bad_expressions_say_what_and_where() {
        for (text, want) in [
            ("", "empty"),
            ("1 +", "ends where"),
            ("(a + b", "expected ')' at the end"),
            ("a + * b", "expected a number, a name or '(' at character 5, found '*'"),
            ("a b", "unexpected 'b' at character 3"),
            ("a % b", "unexpected '%' at character 3"),
            ("expo(a)", "unknown function 'expo'"),
            ("1.2.3", "'1.2.3' is not a number"),
        ] {
            let e = Expression::parse(text).unwrap_err().to_string();
            assert!(e.contains(want), "{text}: {e}");
        }
    }
}
