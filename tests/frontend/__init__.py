"""Frontend tests: AST lowering of Python forms and control flow, print formatting, located errors (a package,
so module names cannot clash with other test folders)."""
