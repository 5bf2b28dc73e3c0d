"""Beyond one machine: k-d bricks composited in visibility order, and time series and bricks
rendered on Dask."""
