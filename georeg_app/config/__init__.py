"""The TOML configuration files of ``georeg measure``, ``compare`` and ``track``, read and checked."""
