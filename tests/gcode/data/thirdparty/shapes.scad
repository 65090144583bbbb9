// Test models for the third-party corpus (make_corpus.py): openscad -D 'shape="cube"' ...
shape = "cube";
if (shape == "cube") cube([20, 20, 10]);
if (shape == "cube_small") cube([12, 12, 5]);
if (shape == "tube") difference() {
  cylinder(h = 5, r = 8, $fn = 64);
  translate([0, 0, -1]) cylinder(h = 7, r = 6, $fn = 64);
}
// the team's fixture part: a hollow cylinder with a boss
if (shape == "part") difference() {
  union() { cylinder(h = 30, r = 40, $fn = 96); translate([0, 0, 30]) cylinder(h = 10, r1 = 25, r2 = 15, $fn = 64); }
  translate([0, 0, -1]) cylinder(h = 50, r = 30, $fn = 96);
}
// a small boat: curved hull, cabin with a round window, chimney (many arcs when sliced with arcs)
if (shape == "boat") {
  hull() {
    translate([-18, 0, 0]) scale([1, 0.6, 1]) cylinder(h = 10, r1 = 8, r2 = 12, $fn = 160);
    translate([16, 0, 0]) scale([1.4, 0.55, 1]) cylinder(h = 10, r1 = 4, r2 = 9, $fn = 160);
  }
  difference() {
    translate([-14, -7, 10]) cube([14, 14, 10]);
    translate([-7, -8, 15]) rotate([-90, 0, 0]) cylinder(h = 16, r = 3, $fn = 96);
    translate([-12, -5, 10.01]) cube([10, 10, 8]);
  }
  translate([-5, 0, 20]) cylinder(h = 8, r = 3, $fn = 120);
}
