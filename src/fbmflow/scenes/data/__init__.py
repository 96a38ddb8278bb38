"""Reference data shipped with the package (literature tables, with their sources)."""
