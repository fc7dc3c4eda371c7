;; render_kernel.wat — the browser viewer's novel-view blend (render.js blendOne: one source's
;; bicubic or bilinear samples, weighted, added to the frame's float32 accumulator) as WebAssembly
;; with 128-bit SIMD: two planes at a time as a pair of doubles, an odd last plane alone. Built into
;; render_kernel.js (base64) by tools/build_web.sh with wabt; render.js falls back to blendOne where
;; WebAssembly SIMD is missing. The same operations in the same order as blendOne, on doubles, with
;; the same float32 roundings: the same accumulator, bit for bit (tests/formats/test_web_decoder.py).
;; Everything is written inline: engines without WebAssembly inlining (Node 20's V8) ran the same
;; code with helper functions 1.6-1.9x slower than blendOne.
(module
  (memory (export "memory") 1)
  ;; blendOne over rows y0..y1 of a W-wide frame: planes `img` (int32, Hp·Wp·P, byte address),
  ;; disparities `disp` (float32, the band's rows), accumulator `acc` (float32, the band's W·P per
  ;; row); dsf, dtf: the source's offset in view steps (float32 values); wf its weight (a float32
  ;; value); `wc`: the byte address of its 6 warp coefficients (doubles) or 0; cubic or bilinear.
  (func (export "blend") (param $img i32) (param $disp i32) (param $acc i32) (param $W i32) (param $H i32)
                         (param $Wp i32) (param $Hp i32) (param $P i32) (param $y0 i32) (param $y1 i32)
                         (param $dsf f32) (param $dtf f32) (param $wf f64) (param $wc i32) (param $cubic i32)
    (local $y i32) (local $x i32) (local $dd f32) (local $Y f32) (local $X f32) (local $Hm f32) (local $Wm f32)
    (local $iy i32) (local $ix i32) (local $fy f64) (local $fx f64) (local $gy f64) (local $gx f64) (local $f1 f64)
    (local $a0 f64) (local $a1 f64) (local $a2 f64) (local $a3 f64) (local $b0 f64) (local $b1 f64) (local $b2 f64) (local $b3 f64)
    (local $A0 v128) (local $A1 v128) (local $A2 v128) (local $A3 v128) (local $wf2 v128)
    (local $V0 v128) (local $V1 v128) (local $V2 v128) (local $V3 v128) (local $v0 f64) (local $v1 f64) (local $v2 f64) (local $v3 f64)
    (local $c0 i32) (local $c1 i32) (local $c2 i32) (local $c3 i32) (local $r0 i32) (local $r1 i32) (local $r2 i32) (local $r3 i32)
    (local $Hp1 i32) (local $Wp1 i32) (local $row i32) (local $P4 i32) (local $p i32) (local $pe i32) (local $ao i32)
    (local $t i32) (local $u i32) (local $yf f64) (local $xf f64)
    (local.set $Hp1 (i32.sub (local.get $Hp) (i32.const 1)))
    (local.set $Wp1 (i32.sub (local.get $Wp) (i32.const 1)))
    (local.set $P4 (i32.shl (local.get $P) (i32.const 2)))                   ;; bytes per pixel
    (local.set $row (i32.mul (local.get $Wp) (local.get $P4)))               ;; bytes per row of planes
    (local.set $pe (i32.shl (i32.and (local.get $P) (i32.const -2)) (i32.const 2)))   ;; bytes of the plane pairs
    (local.set $Hm (f32.convert_i32_s (i32.sub (local.get $H) (i32.const 1))))
    (local.set $Wm (f32.convert_i32_s (i32.sub (local.get $W) (i32.const 1))))
    (local.set $wf2 (f64x2.splat (local.get $wf)))
    (local.set $ao (local.get $acc))
    (local.set $y (local.get $y0))
    (block $ydone (loop $yloop
      (br_if $ydone (i32.ge_s (local.get $y) (local.get $y1)))
      (local.set $yf (f64.convert_i32_s (local.get $y)))
      (local.set $x (i32.const 0))
      (block $xdone (loop $xloop
        (br_if $xdone (i32.ge_s (local.get $x) (local.get $W)))
        ;; the position: Y = f32(y + f32(dd·dsf)), X likewise; plus the warp's offset; clamped to the frame
        (local.set $dd (f32.load (local.get $disp)))
        (local.set $Y (f32.add (f32.convert_i32_s (local.get $y)) (f32.mul (local.get $dd) (local.get $dsf))))
        (local.set $X (f32.add (f32.convert_i32_s (local.get $x)) (f32.mul (local.get $dd) (local.get $dtf))))
        (if (local.get $wc) (then
          (local.set $xf (f64.convert_i32_s (local.get $x)))
          (local.set $Y (f32.add (local.get $Y) (f32.demote_f64 (f64.add (f64.add (f64.mul (f64.load (local.get $wc)) (local.get $yf)) (f64.mul (f64.load offset=8 (local.get $wc)) (local.get $xf))) (f64.load offset=16 (local.get $wc))))))
          (local.set $X (f32.add (local.get $X) (f32.demote_f64 (f64.add (f64.add (f64.mul (f64.load offset=24 (local.get $wc)) (local.get $yf)) (f64.mul (f64.load offset=32 (local.get $wc)) (local.get $xf))) (f64.load offset=40 (local.get $wc))))))))
        (local.set $Y (select (f32.const 0) (select (local.get $Hm) (local.get $Y) (f32.gt (local.get $Y) (local.get $Hm))) (f32.lt (local.get $Y) (f32.const 0))))
        (local.set $X (select (f32.const 0) (select (local.get $Wm) (local.get $X) (f32.gt (local.get $X) (local.get $Wm))) (f32.lt (local.get $X) (f32.const 0))))
        (local.set $iy (i32.trunc_sat_f32_s (local.get $Y)))
        (local.set $ix (i32.trunc_sat_f32_s (local.get $X)))
        (local.set $fy (f64.sub (f64.promote_f32 (local.get $Y)) (f64.convert_i32_s (local.get $iy))))
        (local.set $fx (f64.sub (f64.promote_f32 (local.get $X)) (f64.convert_i32_s (local.get $ix))))
        (local.set $gy (f64.sub (f64.const 1) (local.get $fy)))
        (local.set $gx (f64.sub (f64.const 1) (local.get $fx)))
        (if (local.get $cubic)
          (then
            ;; Keys' weights (a = -0.75) of the taps at -1, 0, +1, +2 (w3 = 1 - w0 - w1 - w2)
            (local.set $a0 (f64.sub (f64.mul (f64.add (f64.mul (f64.sub (f64.mul (f64.const -0.75) (local.tee $f1 (f64.add (local.get $fx) (f64.const 1)))) (f64.const -3.75)) (local.get $f1)) (f64.const -6)) (local.get $f1)) (f64.const -3)))
            (local.set $a1 (f64.add (f64.mul (f64.mul (f64.sub (f64.mul (f64.const 1.25) (local.get $fx)) (f64.const 2.25)) (local.get $fx)) (local.get $fx)) (f64.const 1)))
            (local.set $a2 (f64.add (f64.mul (f64.mul (f64.sub (f64.mul (f64.const 1.25) (local.get $gx)) (f64.const 2.25)) (local.get $gx)) (local.get $gx)) (f64.const 1)))
            (local.set $a3 (f64.sub (f64.sub (f64.sub (f64.const 1) (local.get $a0)) (local.get $a1)) (local.get $a2)))
            (local.set $b0 (f64.sub (f64.mul (f64.add (f64.mul (f64.sub (f64.mul (f64.const -0.75) (local.tee $f1 (f64.add (local.get $fy) (f64.const 1)))) (f64.const -3.75)) (local.get $f1)) (f64.const -6)) (local.get $f1)) (f64.const -3)))
            (local.set $b1 (f64.add (f64.mul (f64.mul (f64.sub (f64.mul (f64.const 1.25) (local.get $fy)) (f64.const 2.25)) (local.get $fy)) (local.get $fy)) (f64.const 1)))
            (local.set $b2 (f64.add (f64.mul (f64.mul (f64.sub (f64.mul (f64.const 1.25) (local.get $gy)) (f64.const 2.25)) (local.get $gy)) (local.get $gy)) (f64.const 1)))
            (local.set $b3 (f64.sub (f64.sub (f64.sub (f64.const 1) (local.get $b0)) (local.get $b1)) (local.get $b2)))
            ;; the taps' columns (byte offsets in a row) and rows (addresses), clamped to the decoded buffer
            (local.set $c0 (i32.mul (select (i32.sub (local.get $ix) (i32.const 1)) (i32.const 0) (i32.gt_s (local.get $ix) (i32.const 0))) (local.get $P4)))
            (local.set $c1 (i32.mul (select (local.get $ix) (local.get $Wp1) (i32.lt_s (local.get $ix) (local.get $Wp1))) (local.get $P4)))
            (local.set $c2 (i32.mul (select (i32.add (local.get $ix) (i32.const 1)) (local.get $Wp1) (i32.lt_s (i32.add (local.get $ix) (i32.const 1)) (local.get $Wp1))) (local.get $P4)))
            (local.set $c3 (i32.mul (select (i32.add (local.get $ix) (i32.const 2)) (local.get $Wp1) (i32.lt_s (i32.add (local.get $ix) (i32.const 2)) (local.get $Wp1))) (local.get $P4)))
            (local.set $r0 (i32.add (local.get $img) (i32.mul (select (i32.sub (local.get $iy) (i32.const 1)) (i32.const 0) (i32.gt_s (local.get $iy) (i32.const 0))) (local.get $row))))
            (local.set $r1 (i32.add (local.get $img) (i32.mul (select (local.get $iy) (local.get $Hp1) (i32.lt_s (local.get $iy) (local.get $Hp1))) (local.get $row))))
            (local.set $r2 (i32.add (local.get $img) (i32.mul (select (i32.add (local.get $iy) (i32.const 1)) (local.get $Hp1) (i32.lt_s (i32.add (local.get $iy) (i32.const 1)) (local.get $Hp1))) (local.get $row))))
            (local.set $r3 (i32.add (local.get $img) (i32.mul (select (i32.add (local.get $iy) (i32.const 2)) (local.get $Hp1) (i32.lt_s (i32.add (local.get $iy) (i32.const 2)) (local.get $Hp1))) (local.get $row))))
            (local.set $A0 (f64x2.splat (local.get $a0)))
            (local.set $A1 (f64x2.splat (local.get $a1)))
            (local.set $A2 (f64x2.splat (local.get $a2)))
            (local.set $A3 (f64x2.splat (local.get $a3)))
            (local.set $p (i32.const 0))
            (block $pdone (loop $ploop
              (br_if $pdone (i32.ge_s (local.get $p) (local.get $pe)))
              (local.set $t (i32.add (local.get $r0) (local.get $p)))
              (local.set $V0 (f64x2.mul (f64x2.splat (local.get $b0)) (f64x2.add (f64x2.add (f64x2.add (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c0)))) (local.get $A0)) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c1)))) (local.get $A1))) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c2)))) (local.get $A2))) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c3)))) (local.get $A3)))))
              (local.set $t (i32.add (local.get $r1) (local.get $p)))
              (local.set $V1 (f64x2.mul (f64x2.splat (local.get $b1)) (f64x2.add (f64x2.add (f64x2.add (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c0)))) (local.get $A0)) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c1)))) (local.get $A1))) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c2)))) (local.get $A2))) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c3)))) (local.get $A3)))))
              (local.set $t (i32.add (local.get $r2) (local.get $p)))
              (local.set $V2 (f64x2.mul (f64x2.splat (local.get $b2)) (f64x2.add (f64x2.add (f64x2.add (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c0)))) (local.get $A0)) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c1)))) (local.get $A1))) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c2)))) (local.get $A2))) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c3)))) (local.get $A3)))))
              (local.set $t (i32.add (local.get $r3) (local.get $p)))
              (local.set $V3 (f64x2.mul (f64x2.splat (local.get $b3)) (f64x2.add (f64x2.add (f64x2.add (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c0)))) (local.get $A0)) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c1)))) (local.get $A1))) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c2)))) (local.get $A2))) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c3)))) (local.get $A3)))))
              (local.set $u (i32.add (local.get $ao) (local.get $p)))
              (v128.store64_lane 0 (local.get $u) (f32x4.demote_f64x2_zero (f64x2.add (f64x2.promote_low_f32x4 (v128.load64_zero (local.get $u))) (f64x2.mul (local.get $wf2) (f64x2.promote_low_f32x4 (f32x4.demote_f64x2_zero (f64x2.add (f64x2.add (f64x2.add (local.get $V0) (local.get $V1)) (local.get $V2)) (local.get $V3))))))))
              (local.set $p (i32.add (local.get $p) (i32.const 8)))
              (br $ploop)))
            (if (i32.lt_s (local.get $p) (local.get $P4)) (then
              (local.set $t (i32.add (local.get $r0) (local.get $p)))
              (local.set $v0 (f64.mul (local.get $b0) (f64.add (f64.add (f64.add (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c0)))) (local.get $a0)) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c1)))) (local.get $a1))) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c2)))) (local.get $a2))) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c3)))) (local.get $a3)))))
              (local.set $t (i32.add (local.get $r1) (local.get $p)))
              (local.set $v1 (f64.mul (local.get $b1) (f64.add (f64.add (f64.add (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c0)))) (local.get $a0)) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c1)))) (local.get $a1))) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c2)))) (local.get $a2))) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c3)))) (local.get $a3)))))
              (local.set $t (i32.add (local.get $r2) (local.get $p)))
              (local.set $v2 (f64.mul (local.get $b2) (f64.add (f64.add (f64.add (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c0)))) (local.get $a0)) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c1)))) (local.get $a1))) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c2)))) (local.get $a2))) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c3)))) (local.get $a3)))))
              (local.set $t (i32.add (local.get $r3) (local.get $p)))
              (local.set $v3 (f64.mul (local.get $b3) (f64.add (f64.add (f64.add (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c0)))) (local.get $a0)) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c1)))) (local.get $a1))) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c2)))) (local.get $a2))) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c3)))) (local.get $a3)))))
              (local.set $u (i32.add (local.get $ao) (local.get $p)))
              (f32.store (local.get $u) (f32.demote_f64 (f64.add (f64.promote_f32 (f32.load (local.get $u))) (f64.mul (local.get $wf) (f64.promote_f32 (f32.demote_f64 (f64.add (f64.add (f64.add (local.get $v0) (local.get $v1)) (local.get $v2)) (local.get $v3)))))))))))
          (else
            ;; bilinear: the taps at floor and floor + 1 (clamped), f32((s00·gx + s01·fx)·gy + (s10·gx + s11·fx)·fy)
            (local.set $c0 (i32.mul (local.get $ix) (local.get $P4)))
            (local.set $c1 (i32.mul (select (i32.add (local.get $ix) (i32.const 1)) (local.get $Wp1) (i32.lt_s (i32.add (local.get $ix) (i32.const 1)) (local.get $Wp1))) (local.get $P4)))
            (local.set $r0 (i32.add (local.get $img) (i32.mul (local.get $iy) (local.get $row))))
            (local.set $r1 (i32.add (local.get $img) (i32.mul (select (i32.add (local.get $iy) (i32.const 1)) (local.get $Hp1) (i32.lt_s (i32.add (local.get $iy) (i32.const 1)) (local.get $Hp1))) (local.get $row))))
            (local.set $A0 (f64x2.splat (local.get $gx)))
            (local.set $A1 (f64x2.splat (local.get $fx)))
            (local.set $A2 (f64x2.splat (local.get $gy)))
            (local.set $A3 (f64x2.splat (local.get $fy)))
            (local.set $p (i32.const 0))
            (block $bdone (loop $bloop
              (br_if $bdone (i32.ge_s (local.get $p) (local.get $pe)))
              (local.set $t (i32.add (local.get $r0) (local.get $p)))
              (local.set $c2 (i32.add (local.get $r1) (local.get $p)))
              (local.set $u (i32.add (local.get $ao) (local.get $p)))
              (v128.store64_lane 0 (local.get $u) (f32x4.demote_f64x2_zero (f64x2.add (f64x2.promote_low_f32x4 (v128.load64_zero (local.get $u))) (f64x2.mul (local.get $wf2) (f64x2.promote_low_f32x4 (f32x4.demote_f64x2_zero (f64x2.add (f64x2.mul (f64x2.add (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c0)))) (local.get $A0)) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $t) (local.get $c1)))) (local.get $A1))) (local.get $A2)) (f64x2.mul (f64x2.add (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $c2) (local.get $c0)))) (local.get $A0)) (f64x2.mul (f64x2.convert_low_i32x4_s (v128.load64_zero (i32.add (local.get $c2) (local.get $c1)))) (local.get $A1))) (local.get $A3)))))))))
              (local.set $p (i32.add (local.get $p) (i32.const 8)))
              (br $bloop)))
            (if (i32.lt_s (local.get $p) (local.get $P4)) (then
              (local.set $t (i32.add (local.get $r0) (local.get $p)))
              (local.set $c2 (i32.add (local.get $r1) (local.get $p)))
              (local.set $u (i32.add (local.get $ao) (local.get $p)))
              (f32.store (local.get $u) (f32.demote_f64 (f64.add (f64.promote_f32 (f32.load (local.get $u))) (f64.mul (local.get $wf) (f64.promote_f32 (f32.demote_f64 (f64.add (f64.mul (f64.add (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c0)))) (local.get $gx)) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $t) (local.get $c1)))) (local.get $fx))) (local.get $gy)) (f64.mul (f64.add (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $c2) (local.get $c0)))) (local.get $gx)) (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $c2) (local.get $c1)))) (local.get $fx))) (local.get $fy)))))))))))))
        (local.set $disp (i32.add (local.get $disp) (i32.const 4)))
        (local.set $ao (i32.add (local.get $ao) (local.get $P4)))
        (local.set $x (i32.add (local.get $x) (i32.const 1)))
        (br $xloop)))
      (local.set $y (i32.add (local.get $y) (i32.const 1)))
      (br $yloop))))

  ;; a frame's planes: each of `n` float32 values at byte `src` rounded to the nearest integer,
  ;; ties to even (render.js rintPlanes' (v + 1.5·2^52) − 1.5·2^52 on the doubles), as int32 at `dst`
  (func (export "rint") (param $src i32) (param $dst i32) (param $n i32)
    (local $i i32) (local $e i32)
    (local.set $e (i32.shl (i32.and (local.get $n) (i32.const -4)) (i32.const 2)))
    (block $done (loop $l
      (br_if $done (i32.ge_u (local.get $i) (local.get $e)))
      (v128.store (i32.add (local.get $dst) (local.get $i))
        (i32x4.trunc_sat_f32x4_s (f32x4.nearest (v128.load (i32.add (local.get $src) (local.get $i))))))
      (local.set $i (i32.add (local.get $i) (i32.const 16)))
      (br $l)))
    (local.set $e (i32.shl (local.get $n) (i32.const 2)))
    (block $tdone (loop $t
      (br_if $tdone (i32.ge_u (local.get $i) (local.get $e)))
      (i32.store (i32.add (local.get $dst) (local.get $i))
        (i32.trunc_sat_f32_s (f32.nearest (f32.load (i32.add (local.get $src) (local.get $i))))))
      (local.set $i (i32.add (local.get $i) (i32.const 4)))
      (br $t))))

  ;; the robust choice's samples of one candidate (render.js _consistent: _sampleGrid's bilinear
  ;; samples of plane 0 of each source at a gh×gw grid of every `step`-th pixel, displaced by the
  ;; candidate disparities D (float32, G), in float32 as there): out (float32, nq·G, source-major).
  ;; Sources: `nq` records of 96 bytes at `src` (planes' byte address (int32), warps? (int32), dsf,
  ;; dtf, wf (doubles holding float32 values), the 6 warp coefficients (doubles)).
  (func (export "samples") (param $D i32) (param $out i32) (param $gh i32) (param $gw i32) (param $step i32)
                        (param $W i32) (param $H i32) (param $Wp i32) (param $Hp i32) (param $P i32)
                        (param $src i32) (param $nq i32) (param $G i32)
    (local $gy i32) (local $gx i32) (local $k i32) (local $q i32) (local $r i32) (local $dd f64) (local $y f64) (local $x f64)
    (local $Y f64) (local $X f64) (local $Hm f64) (local $Wm f64) (local $iy i32) (local $ix i32) (local $fy f64) (local $fx f64)
    (local $y1 i32) (local $x1 i32) (local $img i32) (local $smp f64)
    (local $Hp1 i32) (local $Wp1 i32)
    (local.set $Hm (f64.convert_i32_s (i32.sub (local.get $H) (i32.const 1))))
    (local.set $Wm (f64.convert_i32_s (i32.sub (local.get $W) (i32.const 1))))
    (local.set $Hp1 (i32.sub (local.get $Hp) (i32.const 1)))
    (local.set $Wp1 (i32.sub (local.get $Wp) (i32.const 1)))
    (block $ydone (loop $yloop
      (br_if $ydone (i32.ge_s (local.get $gy) (local.get $gh)))
      (local.set $y (f64.convert_i32_s (i32.mul (local.get $gy) (local.get $step))))
      (local.set $gx (i32.const 0))
      (block $xdone (loop $xloop
        (br_if $xdone (i32.ge_s (local.get $gx) (local.get $gw)))
        (local.set $x (f64.convert_i32_s (i32.mul (local.get $gx) (local.get $step))))
        (local.set $dd (f64.promote_f32 (f32.load (i32.add (local.get $D) (i32.shl (local.get $k) (i32.const 2))))))
        (local.set $q (i32.const 0))
        (block $qdone (loop $qloop
          (br_if $qdone (i32.ge_s (local.get $q) (local.get $nq)))
          (local.set $r (i32.add (local.get $src) (i32.mul (local.get $q) (i32.const 96))))
          ;; Y = f32(y + f32(dd·dsf)), X likewise; plus the warp's offset; clamped to the frame
          (local.set $Y (f64.promote_f32 (f32.demote_f64 (f64.add (local.get $y)
            (f64.promote_f32 (f32.demote_f64 (f64.mul (local.get $dd) (f64.load offset=8 (local.get $r)))))))))
          (local.set $X (f64.promote_f32 (f32.demote_f64 (f64.add (local.get $x)
            (f64.promote_f32 (f32.demote_f64 (f64.mul (local.get $dd) (f64.load offset=16 (local.get $r)))))))))
          (if (i32.load offset=4 (local.get $r)) (then
            (local.set $Y (f64.promote_f32 (f32.demote_f64 (f64.add (local.get $Y) (f64.promote_f32 (f32.demote_f64
              (f64.add (f64.add (f64.mul (f64.load offset=32 (local.get $r)) (local.get $y)) (f64.mul (f64.load offset=40 (local.get $r)) (local.get $x)))
                       (f64.load offset=48 (local.get $r)))))))))
            (local.set $X (f64.promote_f32 (f32.demote_f64 (f64.add (local.get $X) (f64.promote_f32 (f32.demote_f64
              (f64.add (f64.add (f64.mul (f64.load offset=56 (local.get $r)) (local.get $y)) (f64.mul (f64.load offset=64 (local.get $r)) (local.get $x)))
                       (f64.load offset=72 (local.get $r)))))))))))
          (local.set $Y (select (f64.const 0) (select (local.get $Hm) (local.get $Y) (f64.gt (local.get $Y) (local.get $Hm))) (f64.lt (local.get $Y) (f64.const 0))))
          (local.set $X (select (f64.const 0) (select (local.get $Wm) (local.get $X) (f64.gt (local.get $X) (local.get $Wm))) (f64.lt (local.get $X) (f64.const 0))))
          (local.set $iy (i32.trunc_f64_s (f64.floor (local.get $Y))))
          (local.set $ix (i32.trunc_f64_s (f64.floor (local.get $X))))
          (local.set $fy (f64.sub (local.get $Y) (f64.convert_i32_s (local.get $iy))))
          (local.set $fx (f64.sub (local.get $X) (f64.convert_i32_s (local.get $ix))))
          (local.set $y1 (select (i32.add (local.get $iy) (i32.const 1)) (local.get $Hp1) (i32.lt_s (i32.add (local.get $iy) (i32.const 1)) (local.get $Hp1))))
          (local.set $x1 (select (i32.add (local.get $ix) (i32.const 1)) (local.get $Wp1) (i32.lt_s (i32.add (local.get $ix) (i32.const 1)) (local.get $Wp1))))
          (local.set $img (i32.load (local.get $r)))
          ;; (a·(1 − fx) + b·fx)·(1 − fy) + (c·(1 − fx) + e·fx)·fy, plane 0, stored as float32
          (local.set $smp (f64.promote_f32 (f32.demote_f64 (f64.add
            (f64.mul (f64.add (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $img) (i32.shl (i32.mul (i32.add (i32.mul (local.get $iy) (local.get $Wp)) (local.get $ix)) (local.get $P)) (i32.const 2)))))
                                       (f64.sub (f64.const 1) (local.get $fx)))
                              (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $img) (i32.shl (i32.mul (i32.add (i32.mul (local.get $iy) (local.get $Wp)) (local.get $x1)) (local.get $P)) (i32.const 2)))))
                                       (local.get $fx)))
                     (f64.sub (f64.const 1) (local.get $fy)))
            (f64.mul (f64.add (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $img) (i32.shl (i32.mul (i32.add (i32.mul (local.get $y1) (local.get $Wp)) (local.get $ix)) (local.get $P)) (i32.const 2)))))
                                       (f64.sub (f64.const 1) (local.get $fx)))
                              (f64.mul (f64.convert_i32_s (i32.load (i32.add (local.get $img) (i32.shl (i32.mul (i32.add (i32.mul (local.get $y1) (local.get $Wp)) (local.get $x1)) (local.get $P)) (i32.const 2)))))
                                       (local.get $fx)))
                     (local.get $fy))))))
          (f32.store (i32.add (local.get $out) (i32.shl (i32.add (i32.mul (local.get $q) (local.get $G)) (local.get $k)) (i32.const 2)))
            (f32.demote_f64 (local.get $smp)))
          (local.set $q (i32.add (local.get $q) (i32.const 1)))
          (br $qloop)))
        (local.set $k (i32.add (local.get $k) (i32.const 1)))
        (local.set $gx (i32.add (local.get $gx) (i32.const 1)))
        (br $xloop)))
      (local.set $gy (i32.add (local.get $gy) (i32.const 1)))
      (br $yloop))))
)
