"""The built-in control laws: every module here is imported by the registry (one file per law, its
``@register`` line is its registration)."""
