"""Pass and compile-pipeline behaviour seen through whole kernels (promotion, hoisting, scatter privatisation);
unit tests of single passes on hand-built IR are in tests/passes. A package, so module names cannot clash."""
