//! Analytic expressions of the parameters, and models made of them.
//!
//! Syntax: numbers (`2`, `0.5`, `1e-3`), parameter names, `+ - * / ^`, parentheses, the
//! functions `sin cos tan asin acos atan sinh cosh tanh exp ln log log10 log2 sqrt abs floor
//! ceil` (one argument; `log` is the natural logarithm) and `min max atan2 pow` (two arguments),
//! and the constant `pi`. Precedence follows mathematics: `^` binds tightest and is
//! right-associative, and unary minus binds looser than `^`, so `-x^2 = -(x^2)` and
//! `2^-1 = 0.5`.
//!
//! The parser is our own (a Pratt parser compiled to a stack program) rather than a crate:
//! `exmex`, the candidate crate, gives unary minus a higher precedence than `^`
//! (`-x^2 = +x²`), which would silently flip log-densities such as `-x^2/2`, and `evalexpr`
//! evaluates `1/2` as integer division.

use crate::error::{CoreError, Result};

#[derive(Debug, Clone, Copy, PartialEq)]
enum Token {
    Number(f64),
    Name(usize, usize),
    Plus,
    Minus,
    Star,
    Slash,
    Caret,
    Open,
    Close,
    Comma,
}

fn tokenize(source: &str) -> std::result::Result<Vec<(Token, usize)>, String> {
    let bytes = source.as_bytes();
    let mut tokens = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let c = bytes[i];
        let start = i;
        let token = match c {
            b' ' | b'\t' | b'\n' | b'\r' => {
                i += 1;
                continue;
            }
            b'+' => Token::Plus,
            b'-' => Token::Minus,
            b'*' if bytes.get(i + 1) == Some(&b'*') => {
                i += 1;
                Token::Caret
            }
            b'*' => Token::Star,
            b'/' => Token::Slash,
            b'^' => Token::Caret,
            b'(' => Token::Open,
            b')' => Token::Close,
            b',' => Token::Comma,
            b'0'..=b'9' | b'.' => {
                while i < bytes.len() && (bytes[i].is_ascii_digit() || bytes[i] == b'.') {
                    i += 1;
                }
                if i < bytes.len() && (bytes[i] == b'e' || bytes[i] == b'E') {
                    let mut j = i + 1;
                    if j < bytes.len() && (bytes[j] == b'+' || bytes[j] == b'-') {
                        j += 1;
                    }
                    if j < bytes.len() && bytes[j].is_ascii_digit() {
                        i = j;
                        while i < bytes.len() && bytes[i].is_ascii_digit() {
                            i += 1;
                        }
                    }
                }
                let text = &source[start..i];
                let value: f64 = text
                    .parse()
                    .map_err(|_| format!("`{text}` at position {start} is not a number"))?;
                tokens.push((Token::Number(value), start));
                continue;
            }
            c if c.is_ascii_alphabetic() || c == b'_' => {
                while i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'_') {
                    i += 1;
                }
                tokens.push((Token::Name(start, i), start));
                continue;
            }
            _ => {
                let ch = source[i..].chars().next().unwrap_or('?');
                return Err(format!("unexpected character `{ch}` at position {start}"));
            }
        };
        tokens.push((token, start));
        i += 1;
    }
    Ok(tokens)
}

/// One instruction of the compiled stack program.
#[derive(Debug, Clone, Copy)]
enum Instruction {
    Constant(f64),
    Variable(usize),
    Negate,
    Add,
    Subtract,
    Multiply,
    Divide,
    Power,
    Unary(fn(f64) -> f64),
    Binary(fn(f64, f64) -> f64),
}

fn unary_function(name: &str) -> Option<fn(f64) -> f64> {
    Some(match name {
        "sin" => f64::sin,
        "cos" => f64::cos,
        "tan" => f64::tan,
        "asin" => f64::asin,
        "acos" => f64::acos,
        "atan" => f64::atan,
        "sinh" => f64::sinh,
        "cosh" => f64::cosh,
        "tanh" => f64::tanh,
        "exp" => f64::exp,
        "ln" | "log" => f64::ln,
        "log10" => f64::log10,
        "log2" => f64::log2,
        "sqrt" => f64::sqrt,
        "abs" => f64::abs,
        "floor" => f64::floor,
        "ceil" => f64::ceil,
        _ => return None,
    })
}

fn binary_function(name: &str) -> Option<fn(f64, f64) -> f64> {
    Some(match name {
        "min" => f64::min,
        "max" => f64::max,
        "atan2" => f64::atan2,
        "pow" => f64::powf,
        _ => return None,
    })
}

/// How deeply signs, exponents, parentheses and function calls may nest: the parser descends
/// recursively, and a mistyped or hostile expression must become an error, not a stack overflow.
const MAX_NESTING: usize = 256;

struct Parser<'a> {
    source: &'a str,
    tokens: Vec<(Token, usize)>,
    position: usize,
    variables: &'a [String],
    program: Vec<Instruction>,
    used: Vec<bool>,
    /// Nesting depth of the `unary` rule, through which every recursion passes.
    nesting: usize,
}

impl Parser<'_> {
    fn peek(&self) -> Option<Token> {
        self.tokens.get(self.position).map(|t| t.0)
    }

    fn offset(&self) -> usize {
        self.tokens
            .get(self.position)
            .map_or(self.source.len(), |t| t.1)
    }

    fn consume(&mut self, expected: Token, what: &str) -> std::result::Result<(), String> {
        if self.peek() == Some(expected) {
            self.position += 1;
            Ok(())
        } else {
            Err(format!("expected {what} at position {}", self.offset()))
        }
    }

    /// expression := term (("+" | "-") term)*
    fn expression(&mut self) -> std::result::Result<(), String> {
        self.term()?;
        while let Some(op @ (Token::Plus | Token::Minus)) = self.peek() {
            self.position += 1;
            self.term()?;
            self.program.push(if op == Token::Plus {
                Instruction::Add
            } else {
                Instruction::Subtract
            });
        }
        Ok(())
    }

    /// term := unary (("*" | "/") unary)*
    fn term(&mut self) -> std::result::Result<(), String> {
        self.unary()?;
        while let Some(op @ (Token::Star | Token::Slash)) = self.peek() {
            self.position += 1;
            self.unary()?;
            self.program.push(if op == Token::Star {
                Instruction::Multiply
            } else {
                Instruction::Divide
            });
        }
        Ok(())
    }

    /// unary := ("-" | "+") unary | power
    fn unary(&mut self) -> std::result::Result<(), String> {
        if self.nesting == MAX_NESTING {
            return Err(format!(
                "nested more than {MAX_NESTING} levels deep at position {}",
                self.offset()
            ));
        }
        self.nesting += 1;
        let parsed = self.unary_unguarded();
        self.nesting -= 1;
        parsed
    }

    fn unary_unguarded(&mut self) -> std::result::Result<(), String> {
        match self.peek() {
            Some(Token::Minus) => {
                self.position += 1;
                self.unary()?;
                self.program.push(Instruction::Negate);
                Ok(())
            }
            Some(Token::Plus) => {
                self.position += 1;
                self.unary()
            }
            _ => self.power(),
        }
    }

    /// power := primary ("^" unary)?   (right-associative; the exponent may carry a sign)
    fn power(&mut self) -> std::result::Result<(), String> {
        self.primary()?;
        if self.peek() == Some(Token::Caret) {
            self.position += 1;
            self.unary()?;
            self.program.push(Instruction::Power);
        }
        Ok(())
    }

    fn primary(&mut self) -> std::result::Result<(), String> {
        let at = self.offset();
        match self.peek() {
            Some(Token::Number(v)) => {
                self.position += 1;
                self.program.push(Instruction::Constant(v));
                Ok(())
            }
            Some(Token::Open) => {
                self.position += 1;
                self.expression()?;
                self.consume(Token::Close, "`)`")
            }
            Some(Token::Name(start, end)) => {
                self.position += 1;
                let name = &self.source[start..end];
                if self.peek() == Some(Token::Open) {
                    self.position += 1;
                    if let Some(f) = unary_function(name) {
                        self.expression()?;
                        self.consume(Token::Close, "`)` (one argument)")?;
                        self.program.push(Instruction::Unary(f));
                    } else if let Some(f) = binary_function(name) {
                        self.expression()?;
                        self.consume(Token::Comma, "`,` (two arguments)")?;
                        self.expression()?;
                        self.consume(Token::Close, "`)`")?;
                        self.program.push(Instruction::Binary(f));
                    } else {
                        return Err(format!("unknown function `{name}` at position {at}"));
                    }
                    return Ok(());
                }
                if let Some(k) = self.variables.iter().position(|v| v == name) {
                    self.used[k] = true;
                    self.program.push(Instruction::Variable(k));
                } else if name == "pi" || name == "PI" {
                    self.program
                        .push(Instruction::Constant(std::f64::consts::PI));
                } else {
                    return Err(format!(
                        "unknown variable `{name}` at position {at} (known: {})",
                        self.variables.join(", ")
                    ));
                }
                Ok(())
            }
            _ => Err(format!("expected a number, name or `(` at position {at}")),
        }
    }
}

/// A parsed expression over a fixed, ordered list of variables, compiled to a stack program.
#[derive(Debug, Clone)]
pub struct Expression {
    source: String,
    program: Vec<Instruction>,
    stack_depth: usize,
    used_variables: Vec<bool>,
}

impl Expression {
    /// Parse `source`, whose free variables must all be among `variables`.
    pub fn parse(source: &str, variables: &[String]) -> Result<Self> {
        let invalid = |reason: String| CoreError::InvalidExpression {
            expression: source.to_string(),
            reason,
        };
        let tokens = tokenize(source).map_err(invalid)?;
        if tokens.is_empty() {
            return Err(invalid("the expression is empty".into()));
        }
        let mut parser = Parser {
            source,
            tokens,
            position: 0,
            variables,
            program: Vec::new(),
            used: vec![false; variables.len()],
            nesting: 0,
        };
        parser.expression().map_err(invalid)?;
        if parser.position != parser.tokens.len() {
            return Err(invalid(format!(
                "unexpected input at position {}",
                parser.offset()
            )));
        }
        let mut depth: usize = 0;
        let mut stack_depth = 0;
        for instruction in &parser.program {
            match instruction {
                Instruction::Constant(_) | Instruction::Variable(_) => depth += 1,
                Instruction::Negate | Instruction::Unary(_) => {}
                _ => depth -= 1,
            }
            stack_depth = stack_depth.max(depth);
        }
        Ok(Self {
            source: source.to_string(),
            program: parser.program,
            stack_depth,
            used_variables: parser.used,
        })
    }

    /// The text the expression was parsed from.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Whether variable `k` (index into the `variables` given to [`Expression::parse`]) occurs.
    pub fn uses_variable(&self, k: usize) -> bool {
        self.used_variables.get(k).copied().unwrap_or(false)
    }

    /// Evaluate at `values` (ordered as the `variables` given to [`Expression::parse`]).
    /// Domain errors give NaN or ±∞ as IEEE arithmetic does; a missing value is NaN.
    pub fn evaluate(&self, values: &[f64]) -> f64 {
        let mut inline = [0.0f64; 32];
        let mut heap;
        let stack: &mut [f64] = if self.stack_depth <= inline.len() {
            &mut inline
        } else {
            heap = vec![0.0; self.stack_depth];
            &mut heap
        };
        let mut top = 0usize;
        for instruction in &self.program {
            match *instruction {
                Instruction::Constant(v) => {
                    stack[top] = v;
                    top += 1;
                }
                Instruction::Variable(k) => {
                    stack[top] = values.get(k).copied().unwrap_or(f64::NAN);
                    top += 1;
                }
                Instruction::Negate => stack[top - 1] = -stack[top - 1],
                Instruction::Unary(f) => stack[top - 1] = f(stack[top - 1]),
                binary => {
                    top -= 1;
                    let (a, b) = (stack[top - 1], stack[top]);
                    stack[top - 1] = match binary {
                        Instruction::Add => a + b,
                        Instruction::Subtract => a - b,
                        Instruction::Multiply => a * b,
                        Instruction::Divide => a / b,
                        Instruction::Power => power(a, b),
                        Instruction::Binary(f) => f(a, b),
                        _ => f64::NAN,
                    };
                }
            }
        }
        stack[0]
    }
}

/// a^b, with integer exponents by repeated multiplication (exact for `x^2`, and defined for
/// negative bases).
fn power(a: f64, b: f64) -> f64 {
    if b == b.trunc() && b.abs() <= 64.0 {
        a.powi(b as i32)
    } else {
        a.powf(b)
    }
}

use rayon::prelude::*;

use crate::model::{Evaluation, EvaluationFailure, Model, Outcome};

/// A model whose outputs are analytic expressions of its inputs (study key
/// `[model] kind = "expression"`, `outputs = { name = "formula" }`). Cheap: batches are
/// evaluated in parallel in-process, and non-finite values become failures.
#[derive(Debug, Clone)]
pub struct ExpressionModel {
    input_names: Vec<String>,
    output_names: Vec<String>,
    expressions: Vec<Expression>,
}

impl ExpressionModel {
    /// Build the model from `(output name, formula)` pairs over `input_names`.
    pub fn new(input_names: Vec<String>, outputs: &[(String, String)]) -> Result<Self> {
        if outputs.is_empty() {
            return Err(CoreError::InvalidExpression {
                expression: String::new(),
                reason: "an expression model needs at least one output".into(),
            });
        }
        let expressions = outputs
            .iter()
            .map(|(_, formula)| Expression::parse(formula, &input_names))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            input_names,
            output_names: outputs.iter().map(|(n, _)| n.clone()).collect(),
            expressions,
        })
    }

    fn evaluate_point(&self, x: &[f64]) -> Outcome {
        let outputs: Vec<f64> = self.expressions.iter().map(|e| e.evaluate(x)).collect();
        if let Some(k) = outputs.iter().position(|v| !v.is_finite()) {
            return Err(EvaluationFailure::new(format!(
                "output `{}` = `{}` is not finite ({})",
                self.output_names[k],
                self.expressions[k].source(),
                outputs[k]
            )));
        }
        Ok(Evaluation::new(outputs))
    }
}

impl Model for ExpressionModel {
    fn input_names(&self) -> &[String] {
        &self.input_names
    }

    fn output_names(&self) -> &[String] {
        &self.output_names
    }

    fn evaluate_batch(&self, points: &[Vec<f64>]) -> Result<Vec<Outcome>> {
        if let Some(p) = points.iter().find(|p| p.len() != self.input_names.len()) {
            return Err(CoreError::DimensionMismatch {
                expected: self.input_names.len(),
                actual: p.len(),
            });
        }
        Ok(points
            .par_iter()
            .with_min_len(256)
            .map(|x| self.evaluate_point(x))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn ishigami_evaluates_as_written() {
        let vars = names(&["x1", "x2", "x3"]);
        let e = Expression::parse("sin(x1) + 7*sin(x2)^2 + 0.1*x3^4*sin(x1)", &vars).unwrap();
        let x = [0.3, -1.2, 2.5];
        let expected =
            0.3f64.sin() + 7.0 * (-1.2f64).sin().powi(2) + 0.1 * 2.5f64.powi(4) * 0.3f64.sin();
        assert!((e.evaluate(&x) - expected).abs() < 1e-14);
    }

    #[test]
    fn functions_constants_and_precedence() {
        let vars = names(&["a", "b"]);
        let cases = [
            (
                "-(100*(b - a^2)^2 + (a - 1)^2)",
                -(100.0 * (3.0f64 - 4.0).powi(2) + 1.0),
            ),
            ("2*pi", 2.0 * std::f64::consts::PI),
            (
                "ln(b) + log10(100) + sqrt(b) + abs(-a) + exp(0) + tan(0) + cos(0)",
                3f64.ln() + 2.0 + 3f64.sqrt() + 2.0 + 1.0 + 1.0,
            ),
            ("a/b/2", 2.0 / 3.0 / 2.0),
            ("-a^2", -4.0),
            ("a^-1", 0.5),
            ("2^3^2", 512.0),
            ("-(a - b)*2", 2.0),
            ("1/2*a", 1.0),
            ("1.5e1 + .5 + 2E-1", 15.7),
            ("min(a, b) + max(a, b) + atan2(0, 1) + pow(a, 3)", 13.0),
            ("a**2", 4.0),
            ("(-a)^2", 4.0),
            ("a*-b", -6.0),
            ("a/-b^2", -2.0 / 9.0),
        ];
        for (src, expected) in cases {
            let e = Expression::parse(src, &vars).unwrap();
            assert!((e.evaluate(&[2.0, 3.0]) - expected).abs() < 1e-12, "{src}");
        }
    }

    #[test]
    fn deep_nesting_is_an_error_not_a_stack_overflow() {
        let vars = names(&["x"]);
        let depth = MAX_NESTING - 1;
        let nested = format!("{}x{}", "(".repeat(depth), ")".repeat(depth));
        assert_eq!(
            Expression::parse(&nested, &vars).unwrap().evaluate(&[2.0]),
            2.0
        );
        for source in [
            format!("{}x", "-".repeat(100_000)),
            format!("{}x{}", "(".repeat(100_000), ")".repeat(100_000)),
            format!("{}x{}", "sin(".repeat(100_000), ")".repeat(100_000)),
            format!("x{}", "^x".repeat(100_000)),
        ] {
            let err = Expression::parse(&source, &vars).unwrap_err().to_string();
            assert!(
                err.contains(&format!("nested more than {MAX_NESTING} levels")),
                "{err}"
            );
        }
    }

    #[test]
    fn unknown_variables_and_syntax_errors_are_reported() {
        let vars = names(&["x"]);
        let err = Expression::parse("x + y", &vars).unwrap_err().to_string();
        assert!(err.contains("unknown variable `y`"), "{err}");
        assert!(Expression::parse("x + * 2", &vars).is_err());
        assert!(Expression::parse("  ", &vars).is_err());
        assert!(Expression::parse("sin(x", &vars).is_err());
        assert!(Expression::parse("x)", &vars).is_err());
        assert!(
            Expression::parse("foo(x)", &vars)
                .unwrap_err()
                .to_string()
                .contains("unknown function")
        );
        assert!(Expression::parse("min(x)", &vars).is_err());
        assert!(Expression::parse("x $ 2", &vars).is_err());
        assert!(Expression::parse("1.2.3", &vars).is_err());
    }

    #[test]
    fn model_turns_non_finite_outputs_into_failures() {
        let m = ExpressionModel::new(
            names(&["x"]),
            &[("y".into(), "ln(x)".into()), ("z".into(), "2*x".into())],
        )
        .unwrap();
        let out = m
            .evaluate_batch(&[vec![1.0], vec![-1.0], vec![0.0]])
            .unwrap();
        assert_eq!(out[0].as_ref().unwrap().outputs, vec![0.0, 2.0]);
        assert!(out[1].as_ref().unwrap_err().reason.contains("`y`"));
        assert!(out[2].is_err());
        assert!(m.evaluate_batch(&[vec![1.0, 2.0]]).is_err());
    }
}
