"""The compiler stage: the @ti.kernel object (kernel.py) and the compile driver (driver.py).

It sits above every other stage: it drives the frontend, the passes, autodiff, codegen and the runtime,
and nothing below imports it (tests/test_layering.py)."""
