//! `--preset`, shared by `deform` and `loadtest`.

use clap::ValueEnum;
use dend::deform::Preset;

/// A named parameter set (`--preset` of `deform` and `loadtest`):
/// `dend::deform::Preset` on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(super) enum PresetArg {
    /// The default: posing characters (`Preset::Characters`).
    Characters,
    /// The paper's even bend and twist (`Preset::Elastica`; `general` is
    /// its old name).
    #[value(alias = "general")]
    Elastica,
}

impl PresetArg {
    /// The library's preset.
    pub(super) fn preset(self) -> Preset {
        match self {
            PresetArg::Characters => Preset::Characters,
            PresetArg::Elastica => Preset::Elastica,
        }
    }
}
