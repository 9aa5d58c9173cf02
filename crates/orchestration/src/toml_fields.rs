//! Reading TOML tables key by key, so that every problem names its full key path
//! (`excitation.amp_g`, `model.platen.mm`) and all problems are reported together.

use std::collections::BTreeSet;
use std::fmt;

/// One problem in an input file, with the key path (or row) it concerns.
#[derive(Debug, Clone, PartialEq)]
pub struct Issue {
    pub path: String,
    pub message: String,
}

impl fmt::Display for Issue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.path.is_empty() {
            f.write_str(&self.message)
        } else {
            write!(f, "{}: {}", self.path, self.message)
        }
    }
}

/// Every problem found in one input file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct InputError {
    /// The file (or `<string>`).
    pub file: String,
    pub issues: Vec<Issue>,
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.issues.len();
        write!(
            f,
            "{}: {} problem{}",
            self.file,
            n,
            if n == 1 { "" } else { "s" }
        )?;
        for i in &self.issues {
            write!(f, "\n  {i}")?;
        }
        Ok(())
    }
}

/// Collects issues while a file is read.
#[derive(Debug, Default)]
pub struct Issues(pub Vec<Issue>);

impl Issues {
    pub fn push(&mut self, path: impl Into<String>, message: impl Into<String>) {
        self.0.push(Issue {
            path: path.into(),
            message: message.into(),
        });
    }
    pub fn into_result(self, file: &str) -> Result<(), InputError> {
        if self.0.is_empty() {
            Ok(())
        } else {
            Err(InputError {
                file: file.to_string(),
                issues: self.0,
            })
        }
    }
}

/// Parses TOML text; a syntax error becomes an [`InputError`] with line and column.
pub fn parse(text: &str, file: &str) -> Result<toml::Table, InputError> {
    text.parse::<toml::Table>().map_err(|e| {
        let msg = e.message().to_string();
        let loc = e.span().map(|s| {
            let line = text[..s.start].matches('\n').count() + 1;
            let col = s.start - text[..s.start].rfind('\n').map(|p| p + 1).unwrap_or(0) + 1;
            format!("TOML syntax error at line {line}, column {col}")
        });
        InputError {
            file: file.to_string(),
            issues: vec![Issue {
                path: String::new(),
                message: format!(
                    "{}: {msg}",
                    loc.unwrap_or_else(|| "TOML syntax error".into())
                ),
            }],
        }
    })
}

/// A table being read: remembers which keys were used and reports the rest as unknown.
pub struct Fields<'a> {
    path: String,
    table: &'a toml::Table,
    used: BTreeSet<&'a str>,
}

fn join(prefix: &str, key: &str) -> String {
    if prefix.is_empty() {
        key.to_string()
    } else {
        format!("{prefix}.{key}")
    }
}

impl<'a> Fields<'a> {
    pub fn new(path: impl Into<String>, table: &'a toml::Table) -> Self {
        Fields {
            path: path.into(),
            table,
            used: BTreeSet::new(),
        }
    }

    /// Full path of `key` in this table.
    pub(crate) fn path_of(&self, key: &str) -> String {
        join(&self.path, key)
    }

    pub fn has(&self, key: &str) -> bool {
        self.table.contains_key(key)
    }

    fn take(&mut self, key: &str) -> Option<&'a toml::Value> {
        let (k, v) = self.table.get_key_value(key)?;
        self.used.insert(k.as_str());
        Some(v)
    }

    /// The value of `key` as it is, marked as read (for a key of more than one form).
    pub fn value(&mut self, key: &str) -> Option<&'a toml::Value> {
        self.take(key)
    }

    /// A number (integer or float), finite.
    pub fn f64(&mut self, key: &str, issues: &mut Issues) -> Option<f64> {
        let v = self.take(key)?;
        let x = match v {
            toml::Value::Float(x) => *x,
            toml::Value::Integer(i) => *i as f64,
            other => {
                issues.push(
                    self.path_of(key),
                    format!("expected a number, found {}", other.type_str()),
                );
                return None;
            }
        };
        if !x.is_finite() {
            issues.push(self.path_of(key), format!("{x} is not a finite number"));
            return None;
        }
        Some(x)
    }

    /// A value of one TOML type, or an issue naming the key and what was found.
    fn typed<T>(
        &mut self,
        key: &str,
        issues: &mut Issues,
        expected: &str,
        get: impl Fn(&'a toml::Value) -> Option<T>,
    ) -> Option<T> {
        let v = self.take(key)?;
        let out = get(v);
        if out.is_none() {
            issues.push(
                self.path_of(key),
                format!("expected {expected}, found {}", v.type_str()),
            );
        }
        out
    }

    /// A whole number.
    pub(crate) fn int(&mut self, key: &str, issues: &mut Issues) -> Option<i64> {
        self.typed(key, issues, "a whole number", toml::Value::as_integer)
    }

    /// A string.
    pub fn str(&mut self, key: &str, issues: &mut Issues) -> Option<&'a str> {
        self.typed(key, issues, "a string", toml::Value::as_str)
    }

    /// A whole number (`Ok`) or a string (`Err`).
    pub(crate) fn int_or_str(
        &mut self,
        key: &str,
        issues: &mut Issues,
    ) -> Option<Result<i64, &'a str>> {
        self.typed(key, issues, "a whole number or a string", |v| {
            v.as_integer().map(Ok).or_else(|| v.as_str().map(Err))
        })
    }

    /// A boolean.
    pub fn bool(&mut self, key: &str, issues: &mut Issues) -> Option<bool> {
        self.typed(key, issues, "true or false", toml::Value::as_bool)
    }

    /// A sub-table (also accepts an inline table).
    pub fn table(&mut self, key: &str, issues: &mut Issues) -> Option<Fields<'a>> {
        let path = self.path_of(key);
        match self.take(key)? {
            toml::Value::Table(t) => Some(Fields::new(path, t)),
            other => {
                issues.push(
                    path,
                    format!("expected a table, found {}", other.type_str()),
                );
                None
            }
        }
    }

    /// An array of tables (`[[key]]`), each with its path `key[i]`.
    pub fn tables(&mut self, key: &str, issues: &mut Issues) -> Option<Vec<Fields<'a>>> {
        let path = self.path_of(key);
        match self.take(key)? {
            toml::Value::Array(items) => {
                let mut out = Vec::new();
                for (i, v) in items.iter().enumerate() {
                    match v {
                        toml::Value::Table(t) => out.push(Fields::new(format!("{path}[{i}]"), t)),
                        other => issues.push(
                            format!("{path}[{i}]"),
                            format!("expected a table, found {}", other.type_str()),
                        ),
                    }
                }
                Some(out)
            }
            other => {
                issues.push(
                    path,
                    format!(
                        "expected an array of tables ([[{key}]]), found {}",
                        other.type_str()
                    ),
                );
                None
            }
        }
    }

    /// An array whose every element `get` accepts; a bad element is an issue at `key[i]`.
    fn array<T>(
        &mut self,
        key: &str,
        issues: &mut Issues,
        what: &str,
        element: &str,
        get: impl Fn(&'a toml::Value) -> Option<T>,
    ) -> Option<Vec<T>> {
        let path = self.path_of(key);
        let v = self.take(key)?;
        let Some(items) = v.as_array() else {
            issues.push(
                path,
                format!("expected an array of {what}, found {}", v.type_str()),
            );
            return None;
        };
        let mut out = Vec::with_capacity(items.len());
        for (i, item) in items.iter().enumerate() {
            match get(item) {
                Some(x) => out.push(x),
                None => issues.push(
                    format!("{path}[{i}]"),
                    format!("expected {element}, found {item}"),
                ),
            }
        }
        Some(out)
    }

    /// An array of numbers (integers or finite floats).
    pub(crate) fn f64_array(&mut self, key: &str, issues: &mut Issues) -> Option<Vec<f64>> {
        self.array(key, issues, "numbers", "a finite number", |v| match v {
            toml::Value::Float(x) if x.is_finite() => Some(*x),
            toml::Value::Integer(n) => Some(*n as f64),
            _ => None,
        })
    }

    /// An array of strings.
    pub(crate) fn str_array(&mut self, key: &str, issues: &mut Issues) -> Option<Vec<&'a str>> {
        self.array(key, issues, "strings", "a string", toml::Value::as_str)
    }

    /// The keys of this table not read yet, each reported as unknown (with the expected names).
    pub fn finish(self, expected: &[&str], issues: &mut Issues) {
        for key in self.table.keys() {
            if !self.used.contains(key.as_str()) {
                let hint = suggest(key, expected)
                    .map(|s| format!(" (did you mean `{s}`?)"))
                    .unwrap_or_default();
                let list = if expected.is_empty() {
                    String::new()
                } else {
                    format!("; expected one of: {}", expected.join(", "))
                };
                issues.push(self.path_of(key), format!("unknown key{hint}{list}"));
            }
        }
    }

    /// All keys of the table (for tables whose keys are names, like parameter overrides).
    pub fn keys(&self) -> impl Iterator<Item = &'a String> {
        self.table.keys()
    }
}

/// The closest expected name by edit distance, when it is close.
pub fn suggest<'e>(key: &str, expected: &[&'e str]) -> Option<&'e str> {
    expected
        .iter()
        .map(|e| (strsim::levenshtein(key, e), *e))
        .filter(|(d, e)| *d <= 2.max(e.len() / 4))
        .min()
        .map(|(_, e)| e)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_keys_are_named_with_their_path_and_a_suggestion() {
        let t = parse("[a]\nfreq_hz = 3\nfreq_hzz = 4\n", "x.toml").unwrap();
        let mut issues = Issues::default();
        let mut root = Fields::new("", &t);
        let mut a = root.table("a", &mut issues).unwrap();
        assert_eq!(a.f64("freq_hz", &mut issues), Some(3.0));
        a.finish(&["freq_hz"], &mut issues);
        root.finish(&["a"], &mut issues);
        assert_eq!(issues.0.len(), 1);
        assert_eq!(issues.0[0].path, "a.freq_hzz");
        assert!(issues.0[0].message.contains("did you mean `freq_hz`"));
    }

    #[test]
    fn syntax_errors_carry_line_and_column() {
        let e = parse("a = 1\nb = = 2\n", "bad.toml").unwrap_err();
        let s = e.to_string();
        assert!(s.starts_with("bad.toml"), "{s}");
        assert!(s.contains("line 2"), "{s}");
    }
}
