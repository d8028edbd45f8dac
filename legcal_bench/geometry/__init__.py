"""SE(3)/SO(3) tools (Solà's names) and pose conversions. Radians and metres throughout."""
