//! Message definitions as logs carry them: the `.msg` text of a type followed by the definitions of the types it uses,
//! each after a line of `=` and a `MSG: package/Type` line. ROS 1 bags (`message_definition`), MCAP `ros1msg` and
//! `ros2msg` schemas and rosbag2's `message_definitions` table all use this one syntax.
//!
//! A field line is `TYPE NAME` (ROS 2 may add a default value), a constant `TYPE NAME=VALUE` (skipped: constants take
//! no bytes), `#` starts a comment. `TYPE` is a primitive (`bool`, `byte`, `char`, `int8` … `uint64`, `float32`,
//! `float64`, `string`, ROS 1 `time` and `duration`), `Header` (ROS 1 for `std_msgs/Header`), or a message type
//! `package/Type`, `package/msg/Type` or, in a package's own definitions, `Type`; with a suffix `[]`, `[N]` (fixed)
//! or `[<=N]` (bounded, encoded as unbounded), and `string<=N` for bounded strings. Type names are normalized to
//! `package/Type`. Parsing checks that every message type used is defined; errors name the line.

use std::collections::BTreeMap;

/// A definition that does not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("definition of {type_name}: line {line}: {what}")]
pub struct DefinitionError {
    /// The type whose definition this is.
    pub type_name: String,
    /// Line number in the definition text (1-based; 0 for the text as a whole).
    pub line: usize,
    /// What is wrong.
    pub what: String,
}

/// A primitive field type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Primitive {
    /// `bool`, one byte.
    Bool,
    /// `int8`.
    Int8,
    /// `uint8`, `byte` and `char`.
    Uint8,
    /// `int16`.
    Int16,
    /// `uint16`.
    Uint16,
    /// `int32`.
    Int32,
    /// `uint32`.
    Uint32,
    /// `int64`.
    Int64,
    /// `uint64`.
    Uint64,
    /// `float32`.
    Float32,
    /// `float64`.
    Float64,
    /// `string` (and bounded `string<=N`).
    String,
    /// ROS 1 `time`: `u32` seconds and `u32` nanoseconds.
    Time,
    /// ROS 1 `duration`: `i32` seconds and `i32` nanoseconds.
    Duration,
}

impl Primitive {
    fn from_name(name: &str) -> Option<Primitive> {
        Some(match name {
            "bool" => Primitive::Bool,
            "int8" => Primitive::Int8,
            "uint8" | "byte" | "char" => Primitive::Uint8,
            "int16" => Primitive::Int16,
            "uint16" => Primitive::Uint16,
            "int32" => Primitive::Int32,
            "uint32" => Primitive::Uint32,
            "int64" => Primitive::Int64,
            "uint64" => Primitive::Uint64,
            "float32" => Primitive::Float32,
            "float64" => Primitive::Float64,
            "string" => Primitive::String,
            "time" => Primitive::Time,
            "duration" => Primitive::Duration,
            _ => return None,
        })
    }

    /// Size in bytes of one value (strings: their length prefix).
    pub fn size_bytes(self) -> usize {
        match self {
            Primitive::Bool | Primitive::Int8 | Primitive::Uint8 => 1,
            Primitive::Int16 | Primitive::Uint16 => 2,
            Primitive::Int32 | Primitive::Uint32 | Primitive::Float32 | Primitive::String => 4,
            Primitive::Int64 | Primitive::Uint64 | Primitive::Float64 | Primitive::Time | Primitive::Duration => 8,
        }
    }
}

/// A field's type without its array suffix.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FieldType {
    /// A primitive.
    Primitive(Primitive),
    /// A message type, normalized to `package/Type`.
    Message(String),
}

/// Whether a field is one value or several.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arity {
    /// One value.
    Single,
    /// `[N]`: exactly N values, no length on the wire.
    Fixed(usize),
    /// `[]` or `[<=N]`: a `u32` length, then the values.
    Sequence,
}

/// One field of a message type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Field {
    /// The field's name.
    pub name: String,
    /// Its type.
    pub field_type: FieldType,
    /// One value or an array.
    pub arity: Arity,
}

/// Fixed arrays longer than this are refused (a definition is text a file carries, not a promise).
pub const MAX_FIXED_ARRAY: usize = 1 << 20;

/// A type and the definitions of every message type it uses.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Definitions {
    root: String,
    types: BTreeMap<String, Vec<Field>>,
}

/// `package/msg/Type` and `package/Type` as `package/Type`.
pub fn normalize_type(name: &str) -> String {
    match name.split_once("/msg/") {
        Some((package, type_name)) => format!("{package}/{type_name}"),
        None => name.to_owned(),
    }
}

/// `package/Type` and `package/msg/Type` as `package/msg/Type` (the ROS 2 name).
pub fn ros2_type_name(name: &str) -> String {
    let normalized = normalize_type(name);
    match normalized.split_once('/') {
        Some((package, type_name)) => format!("{package}/msg/{type_name}"),
        None => normalized,
    }
}

impl Definitions {
    /// Parses the definition text a log carries for `type_name`.
    ///
    /// # Errors
    /// [`DefinitionError`] naming the line of a field that does not parse, a section without its `MSG:` line, or
    /// a message type used but not defined.
    pub fn parse(type_name: &str, text: &str) -> Result<Definitions, DefinitionError> {
        let root = normalize_type(type_name);
        let error = |line, what: String| DefinitionError { type_name: root.clone(), line, what };
        let mut types = BTreeMap::new();
        let mut current = (root.clone(), Vec::new(), 0usize);
        let mut expect_msg_line = false;
        for (index, line) in text.lines().enumerate() {
            let number = index + 1;
            let trimmed = line.trim();
            if trimmed.len() >= 3 && trimmed.chars().all(|c| c == '=') {
                let (name, fields, _) = std::mem::replace(&mut current, (String::new(), Vec::new(), number));
                types.entry(name).or_insert(fields);
                expect_msg_line = true;
                continue;
            }
            if expect_msg_line {
                if trimmed.is_empty() {
                    continue;
                }
                let Some(name) = trimmed.strip_prefix("MSG:") else {
                    return Err(error(
                        number,
                        "a section after a line of `=` must start with `MSG: package/Type`".into(),
                    ));
                };
                current.0 = normalize_type(name.trim());
                expect_msg_line = false;
                continue;
            }
            let package = current.0.split('/').next().unwrap_or_default().to_owned();
            if let Some(field) = parse_line(trimmed, &package).map_err(|what| error(number, what))? {
                current.1.push(field);
            }
        }
        if expect_msg_line {
            return Err(error(text.lines().count(), "the text ends after a line of `=`".into()));
        }
        types.entry(current.0).or_insert(current.1);
        let definitions = Definitions { root, types };
        definitions.check_used(text)?;
        Ok(definitions)
    }

    /// Every message type a field uses must be defined (`builtin_interfaces/Time` and `Duration` need not be).
    fn check_used(&self, text: &str) -> Result<(), DefinitionError> {
        for fields in self.types.values() {
            for field in fields {
                if let FieldType::Message(used) = &field.field_type
                    && !self.types.contains_key(used)
                    && !is_builtin_time(used)
                {
                    let line = text.lines().position(|line| line.contains(field.name.as_str())).map_or(0, |i| i + 1);
                    let what = format!("field `{}` uses {used}, which the text does not define", field.name);
                    return Err(DefinitionError { type_name: self.root.clone(), line, what });
                }
            }
        }
        Ok(())
    }

    /// The type these definitions are for, as `package/Type`.
    pub fn root(&self) -> &str {
        &self.root
    }

    /// The fields of a message type (`package/Type`), if defined.
    pub fn fields(&self, type_name: &str) -> Option<&[Field]> {
        self.types.get(type_name).map(Vec::as_slice)
    }
}

/// Whether a message type is ROS 2's `builtin_interfaces/Time` or `Duration`.
pub fn is_builtin_time(type_name: &str) -> bool {
    matches!(type_name, "builtin_interfaces/Time" | "builtin_interfaces/Duration")
}

/// One line of a definition: a field, or `None` for blanks, comments and constants.
fn parse_line(line: &str, package: &str) -> Result<Option<Field>, String> {
    if line.is_empty() || line.starts_with('#') {
        return Ok(None);
    }
    let (type_token, rest) =
        line.split_once(char::is_whitespace).ok_or_else(|| format!("`{line}` has no field name"))?;
    let rest = rest.trim_start();
    if let Some((name, _)) = rest.split_once('=')
        && is_identifier(name.trim())
    {
        return Ok(None);
    }
    let rest = rest.split('#').next().unwrap_or_default();
    let name = rest.split_whitespace().next().ok_or_else(|| format!("`{line}` has no field name"))?;
    if !is_identifier(name) {
        return Err(format!("`{name}` is not a field name"));
    }
    let (base, arity) = parse_arity(type_token)?;
    let base = base.split_once("<=").map_or(base, |(base, _)| base);
    let field_type = match (Primitive::from_name(base), base) {
        (Some(primitive), _) => FieldType::Primitive(primitive),
        (None, "wstring") => return Err("wstring fields are not decoded".to_owned()),
        (None, "Header") => FieldType::Message("std_msgs/Header".to_owned()),
        (None, qualified) if qualified.contains('/') => FieldType::Message(normalize_type(qualified)),
        (None, local) if is_identifier(local) => FieldType::Message(format!("{package}/{local}")),
        (None, other) => return Err(format!("`{other}` is not a type")),
    };
    Ok(Some(Field { name: name.to_owned(), field_type, arity }))
}

fn parse_arity(token: &str) -> Result<(&str, Arity), String> {
    let Some(open) = token.find('[') else { return Ok((token, Arity::Single)) };
    let inside = token[open + 1..].strip_suffix(']').ok_or_else(|| format!("`{token}`: unclosed `[`"))?;
    let arity = if inside.is_empty() || inside.starts_with("<=") {
        Arity::Sequence
    } else {
        let n: usize = inside.parse().map_err(|_| format!("`{token}`: `{inside}` is not an array length"))?;
        if n > MAX_FIXED_ARRAY {
            return Err(format!("`{token}`: fixed arrays are limited to {MAX_FIXED_ARRAY} elements"));
        }
        Arity::Fixed(n)
    };
    Ok((&token[..open], arity))
}

fn is_identifier(name: &str) -> bool {
    !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ros1_definition_with_header_and_constants_parses() {
        let text = "uint8 OK=0\nHeader header # the header\nfloat64[3] p\nTarget[] targets\n\
                    ================================================================================\n\
                    MSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n\
                    ================================================================================\n\
                    MSG: acme/Target\nstring<=8 label\nint16[<=4] rcs\n";
        let definitions = Definitions::parse("acme/msg/Scan", text).unwrap();
        assert_eq!(definitions.root(), "acme/Scan");
        let fields = definitions.fields("acme/Scan").unwrap();
        assert_eq!(fields.len(), 3);
        assert_eq!(fields[0].field_type, FieldType::Message("std_msgs/Header".into()));
        assert_eq!(fields[1].arity, Arity::Fixed(3));
        assert_eq!(fields[2].field_type, FieldType::Message("acme/Target".into()));
        assert_eq!(definitions.fields("acme/Target").unwrap()[1].arity, Arity::Sequence);
    }

    #[test]
    fn undefined_type_and_bad_lines_name_the_line() {
        let error = Definitions::parse("a/B", "int32 x\nfoo/Bar y\n").unwrap_err();
        assert_eq!(error.line, 2, "{error}");
        let error = Definitions::parse("a/B", "int32 x\nfloat64[abc] y\n").unwrap_err();
        assert_eq!(error.to_string(), "definition of a/B: line 2: `float64[abc]`: `abc` is not an array length");
        assert!(Definitions::parse("a/B", "int32\n").is_err());
        assert!(Definitions::parse("a/B", "int32 x\n===\nnot a msg line\n").is_err());
    }
}
