"""Programs on top of the library: the command line, pictures with legends, animation, the
VTK comparison and the viewers. Nothing below imports them."""
