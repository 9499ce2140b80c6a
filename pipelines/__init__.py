"""Named pipeline configurations (TOML), shipped with segparam; see default.toml for every key."""
