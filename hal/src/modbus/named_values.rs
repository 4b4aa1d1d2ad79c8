//! Settings chosen by name in the `[bus]` section (`transport = "tcp"`,
//! `word_order = "CDAB"`): one macro for all of them, so each error names its key.

/// Implements `Deserialize` for a value chosen by name, with an error that names the
/// key (serde's internally tagged `[bus]` would otherwise lose it).
macro_rules! named_values {
    ($ty:ty, $key:literal, { $($name:literal => $value:expr),* $(,)? }) => {
        impl<'de> serde::Deserialize<'de> for $ty {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                let s = <std::borrow::Cow<'de, str> as serde::Deserialize>::deserialize(d)?;
                match s.as_ref() {
                    $($name => Ok($value),)*
                    other => Err(serde::de::Error::custom(format!(
                        concat!($key, ": {:?} is not one of ", $(stringify!($name), " "),*),
                        other
                    ))),
                }
            }
        }
    };
}
pub(crate) use named_values;
