"""From the derivation to running code: allocation-free C++ (straight-line programs), the build
of models and solvers into a cache, and the C++ build tree's bindings. Depends on
chaincomp.model and chaincomp.symbolic."""
