"""The optical model and what is built from it: transfer functions, colour maps, the exact
emission-absorption integrals, and the pre-integration tables with their sizes."""
