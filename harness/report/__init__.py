"""Reports: tables, figures, Markdown."""
