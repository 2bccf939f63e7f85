//! `counter_set!`: a set of counters declared once. Each counter is one line (its doc, its field and, inside
//! its Prometheus family, its label value); from that the macro makes the atomic struct the writers count
//! in, its plain copy (the "figures"), `since`/`plus` where a benchmark compares two moments, and the
//! copy's Prometheus families (name, `# HELP`, `# TYPE`, samples). Adding a counter to a set is one line in
//! its declaration, and its metric cannot be forgotten.
//!
//! It lives with the buses, on the ground floor, because the event log counts storage failures with it
//! (`storage_failures.rs`); telemetry, above, declares the other sets. It imports nothing: the families
//! are written through [`MetricSink`], which telemetry's exposition writer implements.

/// Where a counter set writes its Prometheus families (telemetry's exposition writer).
pub(crate) trait MetricSink {
    /// Starts a family: its `# HELP` and `# TYPE` lines.
    fn family(&mut self, name: &str, kind: &str, help: &str);
    /// One sample line of the family `name`.
    fn sample(&mut self, name: &str, labels: &[(&str, &str)], value: f64);
}

/// Declares a set of counters once.
///
/// ```text
/// counter_set! {
///     /// Doc of the copy.
///     pub struct Figures;
///     /// Doc of the atomic struct (optional: a set gathered from several owners has none).
///     atomic pub(crate) struct Counters;
///     arithmetic #[cfg(..)];           // optional: `since` and `plus` (u64 fields), under these attributes
///     "pavlov_x" gauge "Help." {       // a family of one unlabelled sample…
///         /// Doc of the field.
///         pub x: u64,
///     }
///     "pavlov_y_total" counter "Help." by "reason" {   // …or of one sample per field, labelled
///         /// Doc of the field.
///         pub y_a: u64 = "a",
///         pub y_b: u64 = "b",
///     }
/// }
/// ```
///
/// The families are written in the order declared, each family's samples and the copy's fields in the
/// same order; metric names, help and labels go to `/metrics` exactly as written here. The copy derives
/// `Debug, Clone, Copy, Default, PartialEq, Eq, Serialize`; the atomic struct `Debug, Default` and has
/// `figures()`, the copy now.
macro_rules! counter_set {
    (@family $e:ident, $f:ident, $kind:ident, $name:literal, $help:literal, [], [$field:ident []]) => {
        $e.family($name, stringify!($kind), $help);
        $e.sample($name, &[], $f.$field as f64);
    };
    (@family $e:ident, $f:ident, $kind:ident, $name:literal, $help:literal, [$label:literal],
        [$( $field:ident [$value:literal] ),*]) => {
        $e.family($name, stringify!($kind), $help);
        $( $e.sample($name, &[($label, $value)], $f.$field as f64); )*
    };
    (@atomic $F:ident, [$( $(#[$doc:meta])* $field:ident, )*], ) => {};
    (@atomic $F:ident, [$( $(#[$doc:meta])* $field:ident, )*],
        $(#[$ameta:meta])* $avis:vis struct $A:ident) => {
        $(#[$ameta])*
        #[derive(Debug, Default)]
        $avis struct $A {
            $( $(#[$doc])* pub(crate) $field: ::std::sync::atomic::AtomicU64, )*
        }

        impl $A {
            /// The figures now.
            pub(crate) fn figures(&self) -> $F {
                $F {
                    $( $field: self.$field.load(::std::sync::atomic::Ordering::Relaxed), )*
                }
            }
        }
    };
    (@arithmetic $F:ident, [$( $field:ident, )*], ) => {};
    (@arithmetic $F:ident, [$( $field:ident, )*], [$(#[$arith:meta])*]) => {
        /// Figures are counts since the server started, so two can be subtracted (what happened
        /// between them) and added (two runs as one).
        $(#[$arith])*
        impl $F {
            /// Each count combined with the same count of `other` by `f`.
            fn zip_with(self, other: $F, f: impl Fn(u64, u64) -> u64) -> $F {
                $F {
                    $( $field: f(self.$field, other.$field), )*
                }
            }

            /// What was counted after `earlier`, a copy of the same counters.
            pub(crate) fn since(self, earlier: $F) -> $F {
                self.zip_with(earlier, u64::saturating_sub)
            }

            /// The counts of both.
            pub(crate) fn plus(self, other: $F) -> $F {
                self.zip_with(other, u64::saturating_add)
            }
        }
    };
    (
        $(#[$fmeta:meta])*
        $fvis:vis struct $Figures:ident;
        $( $(#[$ameta:meta])* atomic $avis:vis struct $Atomic:ident; )?
        $( arithmetic $(#[$arith:meta])* ; )?
        $(
            $name:literal $kind:ident $help:literal $( by $label:literal )? {
                $( $(#[$doc:meta])* $vis:vis $field:ident : $ty:ty $( = $value:literal )? ),* $(,)?
            }
        )*
    ) => {
        $(#[$fmeta])*
        #[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ::serde::Serialize)]
        $fvis struct $Figures {
            $( $( $(#[$doc])* $vis $field: $ty, )* )*
        }

        impl $Figures {
            /// Writes the figures' Prometheus families into `e`.
            pub(crate) fn expose(&self, e: &mut impl $crate::bus::counter_set::MetricSink) {
                $( $crate::bus::counter_set::counter_set!(
                    @family e, self, $kind, $name, $help, [$($label)?], [$( $field [$($value)?] ),*]
                ); )*
            }
        }

        $crate::bus::counter_set::counter_set!(
            @atomic $Figures, [$( $( $(#[$doc])* $field, )* )*], $( $(#[$ameta])* $avis struct $Atomic )?
        );
        $crate::bus::counter_set::counter_set!(
            @arithmetic $Figures, [$( $( $field, )* )*], $( [$(#[$arith])*] )?
        );
    };
}

pub(crate) use counter_set;

#[cfg(test)]
mod tests {
    use std::sync::atomic::Ordering;

    use super::*;

    counter_set! {
        /// A copy.
        struct Figures;
        /// The atomic set.
        atomic struct Counters;
        arithmetic;
        "x_now" gauge "Things now." {
            /// Things now.
            now: u64,
        }
        "x_total" counter "Things by kind." by "kind" {
            /// Kind a.
            a: u64 = "a",
            /// Kind b.
            b: u64 = "b",
        }
    }

    /// Writes what it is given as plain lines, to see the calls in order.
    #[derive(Default)]
    struct Lines(Vec<String>);

    impl MetricSink for Lines {
        fn family(&mut self, name: &str, kind: &str, help: &str) {
            self.0.push(format!("family {name} {kind} {help}"));
        }
        fn sample(&mut self, name: &str, labels: &[(&str, &str)], value: f64) {
            self.0.push(format!("sample {name} {labels:?} {value}"));
        }
    }

    #[test]
    fn a_set_counts_copies_subtracts_adds_and_writes_its_families_in_order() {
        let c = Counters::default();
        c.now.store(4, Ordering::Relaxed);
        c.a.fetch_add(2, Ordering::Relaxed);
        let earlier = c.figures();
        c.a.fetch_add(3, Ordering::Relaxed);
        c.b.fetch_add(1, Ordering::Relaxed);
        let later = c.figures();
        assert_eq!(later, Figures { now: 4, a: 5, b: 1 });
        assert_eq!(later.since(earlier), Figures { now: 0, a: 3, b: 1 });
        assert_eq!(later.since(earlier).plus(earlier), later);
        assert_eq!(earlier.since(later), Figures::default());
        let mut lines = Lines::default();
        later.expose(&mut lines);
        assert_eq!(
            lines.0,
            [
                "family x_now gauge Things now.",
                "sample x_now [] 4",
                "family x_total counter Things by kind.",
                "sample x_total [(\"kind\", \"a\")] 5",
                "sample x_total [(\"kind\", \"b\")] 1",
            ]
        );
    }
}
