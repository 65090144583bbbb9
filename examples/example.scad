// The README's example part: a small cup (28 mm across, 8 mm tall, 1.2 mm floor),
// sliced for this machine: see examples/README.md.
difference() {
  cylinder(h = 8, r = 14, $fn = 96);
  translate([0, 0, 1.2]) cylinder(h = 8, r = 12, $fn = 96);
}
