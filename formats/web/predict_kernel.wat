;; predict_kernel.wat — the browser viewer's view prediction (lfc.js TxDecoder._predictTb: each
;; 8×8 transform block of a view as the weighted sum of its key views' bilinear taps, in 1/16 px)
;; as WebAssembly with 128-bit SIMD, four plane samples at a time. Built into predict_kernel.js
;; (base64) by tools/build_kernels.mjs with wabt; lfc.js keeps the loops where WebAssembly SIMD
;; is missing. Integer arithmetic in _predictTb's order (every value fits 32 bits): the same
;; planes, bit for bit (tests/formats/test_web_decoder.py). Written inline (no helper calls:
;; Node 20's V8 does not inline WebAssembly calls).
;;
;; A tb's residual (lfc.js residual + _addResidual: levels dequantized, the 8×8 inverse transform
;; in two passes, added to the prediction and clipped) the same way: the first pass in int32
;; (|Σ| ≤ 479·(2^21 − 1) + 64 < 2^31), the second on doubles (exact: every product and sum is an
;; integer below 2^53), the dequantization in int64.
;;
;; Memory (bytes): the accumulator at 64 (64·P int32), a window's clamped copy at 2048 (9·9·P
;; int32), X, Y and R (64 int32 each) at 3456, 3712, 3968, set by the caller: the zigzag scan
;; (64 int32) at 4224, the transform T8 (row-major, 64 int32) at 4480 and as doubles at 4736;
;; per plane [step16, bypass, lo, hi, flat] (int32) at 5248; the caller's tables, views and key
;; planes from 8192.
(module
  (memory (export "memory") 1)
  ;; `n` rows of 8 int32 at byte address `tab`, one per (tb, key view), a tb's rows together:
  ;; the key view's planes (byte address; int32, Hp·Wp·P), ry, rx (the window's top-left pixel),
  ;; fy, fx (1/16 px), the weight (of 64; 0: none), the tb's byte address in the output planes
  ;; (int32, Wp·P per row), flags (1: the tb's first row, the accumulator starts at 0; 2: its last,
  ;; the prediction (acc + 32) >> 6 is stored; 4: the window crosses the planes' edge, whose
  ;; pixels then repeat).
  (func (export "predict") (param $tab i32) (param $n i32) (param $Hp i32) (param $Wp i32) (param $P i32)
    (local $r i32) (local $end i32) (local $kp i32) (local $ry i32) (local $rx i32) (local $fy i32) (local $fx i32)
    (local $w i32) (local $out i32) (local $fl i32) (local $P4 i32) (local $nb i32) (local $ostride i32)
    (local $src i32) (local $stride i32) (local $a i32) (local $acc i32) (local $i i32) (local $y i32)
    (local $yy i32) (local $xx i32) (local $cy i32) (local $cx i32) (local $q i32) (local $s i32) (local $wb i32)
    (local $W00 v128) (local $W01 v128) (local $W10 v128) (local $W11 v128) (local $WW v128) (local $v v128)
    (local.set $P4 (i32.shl (local.get $P) (i32.const 2)))                  ;; bytes per pixel
    (local.set $nb (i32.shl (local.get $P) (i32.const 5)))                  ;; bytes of a tb's row: 8·P int32
    (local.set $ostride (i32.mul (local.get $Wp) (local.get $P4)))          ;; bytes per row of planes
    (local.set $r (local.get $tab))
    (local.set $end (i32.add (local.get $tab) (i32.shl (local.get $n) (i32.const 5))))
    (block $rdone (loop $rloop
      (br_if $rdone (i32.ge_u (local.get $r) (local.get $end)))
      (local.set $kp (i32.load (local.get $r)))
      (local.set $ry (i32.load offset=4 (local.get $r)))
      (local.set $rx (i32.load offset=8 (local.get $r)))
      (local.set $fy (i32.load offset=12 (local.get $r)))
      (local.set $fx (i32.load offset=16 (local.get $r)))
      (local.set $w (i32.load offset=20 (local.get $r)))
      (local.set $out (i32.load offset=24 (local.get $r)))
      (local.set $fl (i32.load offset=28 (local.get $r)))
      (if (i32.and (local.get $fl) (i32.const 1)) (then                     ;; a new tb: acc = 0
        (local.set $i (i32.const 0))
        (block $zdone (loop $zloop
          (br_if $zdone (i32.ge_u (local.get $i) (i32.shl (local.get $nb) (i32.const 3))))
          (v128.store offset=64 (local.get $i) (v128.const i32x4 0 0 0 0))
          (local.set $i (i32.add (local.get $i) (i32.const 16)))
          (br $zloop)))))
      (if (local.get $w) (then
        (if (i32.and (local.get $fl) (i32.const 4))
          (then
            ;; the 9×9 window with its rows and columns clamped to the planes, copied to byte 2048
            (local.set $wb (i32.const 2048))
            (local.set $yy (i32.const 0))
            (block $gydone (loop $gyloop
              (br_if $gydone (i32.ge_s (local.get $yy) (i32.const 9)))
              (local.set $cy (i32.add (local.get $ry) (local.get $yy)))
              (local.set $cy (select (i32.const 0) (local.get $cy) (i32.lt_s (local.get $cy) (i32.const 0))))
              (local.set $cy (select (i32.sub (local.get $Hp) (i32.const 1)) (local.get $cy)
                                     (i32.ge_s (local.get $cy) (local.get $Hp))))
              (local.set $xx (i32.const 0))
              (block $gxdone (loop $gxloop
                (br_if $gxdone (i32.ge_s (local.get $xx) (i32.const 9)))
                (local.set $cx (i32.add (local.get $rx) (local.get $xx)))
                (local.set $cx (select (i32.const 0) (local.get $cx) (i32.lt_s (local.get $cx) (i32.const 0))))
                (local.set $cx (select (i32.sub (local.get $Wp) (i32.const 1)) (local.get $cx)
                                       (i32.ge_s (local.get $cx) (local.get $Wp))))
                (local.set $a (i32.add (local.get $kp) (i32.mul (i32.add (i32.mul (local.get $cy) (local.get $Wp))
                                                                         (local.get $cx)) (local.get $P4))))
                (local.set $q (i32.const 0))
                (block $gpdone (loop $gploop
                  (br_if $gpdone (i32.ge_s (local.get $q) (local.get $P4)))
                  (i32.store (i32.add (local.get $wb) (local.get $q)) (i32.load (i32.add (local.get $a) (local.get $q))))
                  (local.set $q (i32.add (local.get $q) (i32.const 4)))
                  (br $gploop)))
                (local.set $wb (i32.add (local.get $wb) (local.get $P4)))
                (local.set $xx (i32.add (local.get $xx) (i32.const 1)))
                (br $gxloop)))
              (local.set $yy (i32.add (local.get $yy) (i32.const 1)))
              (br $gyloop)))
            (local.set $src (i32.const 2048))
            (local.set $stride (i32.mul (i32.const 9) (local.get $P4))))
          (else
            (local.set $src (i32.add (local.get $kp) (i32.mul (i32.add (i32.mul (local.get $ry) (local.get $Wp))
                                                                       (local.get $rx)) (local.get $P4))))
            (local.set $stride (local.get $ostride))))
        ;; the taps' weights (16 − fx)(16 − fy), fx(16 − fy), (16 − fx)fy, fx·fy, and the key's weight
        (local.set $W00 (i32x4.splat (i32.mul (i32.sub (i32.const 16) (local.get $fx)) (i32.sub (i32.const 16) (local.get $fy)))))
        (local.set $W01 (i32x4.splat (i32.mul (local.get $fx) (i32.sub (i32.const 16) (local.get $fy)))))
        (local.set $W10 (i32x4.splat (i32.mul (i32.sub (i32.const 16) (local.get $fx)) (local.get $fy))))
        (local.set $W11 (i32x4.splat (i32.mul (local.get $fx) (local.get $fy))))
        (local.set $WW (i32x4.splat (local.get $w)))
        (local.set $acc (i32.const 64))
        (local.set $y (i32.const 0))
        (block $ydone (loop $yloop
          (br_if $ydone (i32.ge_s (local.get $y) (i32.const 8)))
          (local.set $a (local.get $src))
          (local.set $s (i32.add (local.get $src) (local.get $stride)))   ;; the row below
          (local.set $i (i32.const 0))
          (block $idone (loop $iloop
            (br_if $idone (i32.ge_u (local.get $i) (local.get $nb)))
            ;; acc += w·((a·w00 + b·w01 + c·w10 + e·w11 + 128) >> 8), b and e one pixel right
            (local.set $v
              (i32x4.shr_s
                (i32x4.add
                  (i32x4.add
                    (i32x4.add (i32x4.mul (v128.load (i32.add (local.get $a) (local.get $i))) (local.get $W00))
                               (i32x4.mul (v128.load (i32.add (i32.add (local.get $a) (local.get $i)) (local.get $P4))) (local.get $W01)))
                    (i32x4.add (i32x4.mul (v128.load (i32.add (local.get $s) (local.get $i))) (local.get $W10))
                               (i32x4.mul (v128.load (i32.add (i32.add (local.get $s) (local.get $i)) (local.get $P4))) (local.get $W11))))
                  (v128.const i32x4 128 128 128 128))
                (i32.const 8)))
            (v128.store (i32.add (local.get $acc) (local.get $i))
              (i32x4.add (v128.load (i32.add (local.get $acc) (local.get $i))) (i32x4.mul (local.get $WW) (local.get $v))))
            (local.set $i (i32.add (local.get $i) (i32.const 16)))
            (br $iloop)))
          (local.set $src (local.get $s))
          (local.set $acc (i32.add (local.get $acc) (local.get $nb)))
          (local.set $y (i32.add (local.get $y) (i32.const 1)))
          (br $yloop)))))
      (if (i32.and (local.get $fl) (i32.const 2)) (then                     ;; the tb's prediction: (acc + 32) >> 6
        (local.set $acc (i32.const 64))
        (local.set $y (i32.const 0))
        (block $sdone (loop $sloop
          (br_if $sdone (i32.ge_s (local.get $y) (i32.const 8)))
          (local.set $i (i32.const 0))
          (block $jdone (loop $jloop
            (br_if $jdone (i32.ge_u (local.get $i) (local.get $nb)))
            (v128.store (i32.add (local.get $out) (local.get $i))
              (i32x4.shr_s (i32x4.add (v128.load (i32.add (local.get $acc) (local.get $i))) (v128.const i32x4 32 32 32 32))
                           (i32.const 6)))
            (local.set $i (i32.add (local.get $i) (i32.const 16)))
            (br $jloop)))
          (local.set $out (i32.add (local.get $out) (local.get $ostride)))
          (local.set $acc (i32.add (local.get $acc) (local.get $nb)))
          (local.set $y (i32.add (local.get $y) (i32.const 1)))
          (br $sloop)))))
      (local.set $r (i32.add (local.get $r) (i32.const 32)))
      (br $rloop))))
  ;; `nt` tbs of parsed levels at `lev` (int32, nt·P·64: per tb and plane, in scan order); per tb
  ;; at `tbs` its mode (0 skip, 1 inter, 2 intra) and its byte address in the planes (int32, Wp·P
  ;; per row), whose prediction the residual is added to (an intra tb: to the plane's flat value).
  (func (export "residual") (param $lev i32) (param $tbs i32) (param $nt i32) (param $P i32) (param $Wp i32)
    (local $t i32) (local $p i32) (local $mode i32) (local $out i32) (local $pp i32) (local $step i64) (local $bp i32)
    (local $lo i32) (local $hi i32) (local $nz i32) (local $i i32) (local $k i32) (local $q i32) (local $v i64)
    (local $at i32) (local $a i32) (local $b i32) (local $y i32) (local $x i32) (local $P4 i32) (local $ostride i32)
    (local $s0 v128) (local $s1 v128) (local $f0 v128) (local $f1 v128) (local $f2 v128) (local $f3 v128) (local $yk v128)
    (local.set $P4 (i32.shl (local.get $P) (i32.const 2)))
    (local.set $ostride (i32.mul (local.get $Wp) (local.get $P4)))
    (local.set $t (i32.const 0))
    (block $tdone (loop $tloop
      (br_if $tdone (i32.ge_s (local.get $t) (local.get $nt)))
      (local.set $mode (i32.load (i32.add (local.get $tbs) (i32.shl (local.get $t) (i32.const 3)))))
      (local.set $out (i32.load offset=4 (i32.add (local.get $tbs) (i32.shl (local.get $t) (i32.const 3)))))
      (local.set $p (i32.const 0))
      (block $pdone (loop $ploop
        (br_if $pdone (i32.ge_s (local.get $p) (local.get $P)))
        (local.set $pp (i32.add (i32.const 5248) (i32.mul (local.get $p) (i32.const 20))))
        (local.set $step (i64.extend_i32_s (i32.load (local.get $pp))))
        (local.set $bp (i32.load offset=4 (local.get $pp)))
        (local.set $lo (i32.load offset=8 (local.get $pp)))
        (local.set $hi (i32.load offset=12 (local.get $pp)))
        (local.set $nz (i32.const 0))
        (if (local.get $mode) (then
          ;; X = the levels dequantized, min((|q|·step16 + 8) >> 4, 2^21 − 1) with q's sign, at
          ;; their raster positions (the zigzag scan; a bypassed plane keeps the scan order)
          (local.set $i (i32.const 0))
          (block $z0done (loop $z0loop
            (br_if $z0done (i32.ge_u (local.get $i) (i32.const 256)))
            (v128.store offset=3456 (local.get $i) (v128.const i32x4 0 0 0 0))
            (local.set $i (i32.add (local.get $i) (i32.const 16)))
            (br $z0loop)))
          (local.set $a (i32.add (local.get $lev) (i32.shl (i32.add (i32.mul (local.get $t) (local.get $P)) (local.get $p)) (i32.const 8))))
          (local.set $i (i32.const 0))
          (block $ddone (loop $dloop
            (br_if $ddone (i32.ge_u (local.get $i) (i32.const 64)))
            (local.set $q (i32.load (i32.add (local.get $a) (i32.shl (local.get $i) (i32.const 2)))))
            (if (local.get $q) (then
              (local.set $v (i64.shr_u (i64.add (i64.mul (i64.extend_i32_u (select (i32.sub (i32.const 0) (local.get $q)) (local.get $q)
                                                                                      (i32.lt_s (local.get $q) (i32.const 0))))
                                                         (local.get $step)) (i64.const 8)) (i64.const 4)))
              (local.set $v (select (i64.const 2097151) (local.get $v) (i64.gt_u (local.get $v) (i64.const 2097151))))
              (local.set $at (select (local.get $i) (i32.load offset=4224 (i32.shl (local.get $i) (i32.const 2))) (local.get $bp)))
              (i32.store offset=3456 (i32.shl (local.get $at) (i32.const 2))
                (select (i32.sub (i32.const 0) (i32.wrap_i64 (local.get $v))) (i32.wrap_i64 (local.get $v)) (i32.lt_s (local.get $q) (i32.const 0))))
              (local.set $nz (i32.const 1))))
            (local.set $i (i32.add (local.get $i) (i32.const 1)))
            (br $dloop)))
          (if (local.get $nz) (then
            (if (local.get $bp)
              (then                                                          ;; R = X
                (local.set $i (i32.const 0))
                (block $cdone (loop $cloop
                  (br_if $cdone (i32.ge_u (local.get $i) (i32.const 256)))
                  (v128.store offset=3968 (local.get $i) (v128.load offset=3456 (local.get $i)))
                  (local.set $i (i32.add (local.get $i) (i32.const 16)))
                  (br $cloop))))
              (else
                ;; Y = (Tᵀ X + 64) >> 7: row i of Y = Σ_k T[k][i] · row k of X (int32)
                (local.set $i (i32.const 0))
                (block $y1done (loop $y1loop
                  (br_if $y1done (i32.ge_u (local.get $i) (i32.const 8)))
                  (local.set $s0 (v128.const i32x4 64 64 64 64))
                  (local.set $s1 (v128.const i32x4 64 64 64 64))
                  (local.set $k (i32.const 0))
                  (block $k1done (loop $k1loop
                    (br_if $k1done (i32.ge_u (local.get $k) (i32.const 8)))
                    (local.set $yk (i32x4.splat (i32.load offset=4480 (i32.shl (i32.add (i32.shl (local.get $k) (i32.const 3)) (local.get $i)) (i32.const 2)))))
                    (local.set $s0 (i32x4.add (local.get $s0) (i32x4.mul (local.get $yk) (v128.load offset=3456 (i32.shl (local.get $k) (i32.const 5))))))
                    (local.set $s1 (i32x4.add (local.get $s1) (i32x4.mul (local.get $yk) (v128.load offset=3472 (i32.shl (local.get $k) (i32.const 5))))))
                    (local.set $k (i32.add (local.get $k) (i32.const 1)))
                    (br $k1loop)))
                  (v128.store offset=3712 (i32.shl (local.get $i) (i32.const 5)) (i32x4.shr_s (local.get $s0) (i32.const 7)))
                  (v128.store offset=3728 (i32.shl (local.get $i) (i32.const 5)) (i32x4.shr_s (local.get $s1) (i32.const 7)))
                  (local.set $i (i32.add (local.get $i) (i32.const 1)))
                  (br $y1loop)))
                ;; R = (Y T + 128) >> 8: row i of R = Σ_k Y[i][k] · row k of T (doubles, exact), floored
                (local.set $i (i32.const 0))
                (block $y2done (loop $y2loop
                  (br_if $y2done (i32.ge_u (local.get $i) (i32.const 8)))
                  (local.set $f0 (v128.const f64x2 128 128))
                  (local.set $f1 (v128.const f64x2 128 128))
                  (local.set $f2 (v128.const f64x2 128 128))
                  (local.set $f3 (v128.const f64x2 128 128))
                  (local.set $k (i32.const 0))
                  (block $k2done (loop $k2loop
                    (br_if $k2done (i32.ge_u (local.get $k) (i32.const 8)))
                    (local.set $yk (f64x2.splat (f64.convert_i32_s (i32.load offset=3712 (i32.shl (i32.add (i32.shl (local.get $i) (i32.const 3)) (local.get $k)) (i32.const 2))))))
                    (local.set $b (i32.shl (local.get $k) (i32.const 6)))         ;; row k of T as doubles
                    (local.set $f0 (f64x2.add (local.get $f0) (f64x2.mul (local.get $yk) (v128.load offset=4736 (local.get $b)))))
                    (local.set $f1 (f64x2.add (local.get $f1) (f64x2.mul (local.get $yk) (v128.load offset=4752 (local.get $b)))))
                    (local.set $f2 (f64x2.add (local.get $f2) (f64x2.mul (local.get $yk) (v128.load offset=4768 (local.get $b)))))
                    (local.set $f3 (f64x2.add (local.get $f3) (f64x2.mul (local.get $yk) (v128.load offset=4784 (local.get $b)))))
                    (local.set $k (i32.add (local.get $k) (i32.const 1)))
                    (br $k2loop)))
                  (local.set $b (i32.shl (local.get $i) (i32.const 5)))
                  (v128.store64_lane offset=3968 0 (local.get $b)
                    (i32x4.trunc_sat_f64x2_s_zero (f64x2.floor (f64x2.mul (local.get $f0) (v128.const f64x2 0.00390625 0.00390625)))))
                  (v128.store64_lane offset=3976 0 (local.get $b)
                    (i32x4.trunc_sat_f64x2_s_zero (f64x2.floor (f64x2.mul (local.get $f1) (v128.const f64x2 0.00390625 0.00390625)))))
                  (v128.store64_lane offset=3984 0 (local.get $b)
                    (i32x4.trunc_sat_f64x2_s_zero (f64x2.floor (f64x2.mul (local.get $f2) (v128.const f64x2 0.00390625 0.00390625)))))
                  (v128.store64_lane offset=3992 0 (local.get $b)
                    (i32x4.trunc_sat_f64x2_s_zero (f64x2.floor (f64x2.mul (local.get $f3) (v128.const f64x2 0.00390625 0.00390625)))))
                  (local.set $i (i32.add (local.get $i) (i32.const 1)))
                  (br $y2loop)))))))))
        ;; the plane's 8×8 samples: (intra: the flat value; else the prediction) + R, clipped
        (local.set $a (i32.add (local.get $out) (i32.shl (local.get $p) (i32.const 2))))
        (local.set $i (i32.const 0))
        (local.set $y (i32.const 0))
        (block $ady (loop $aly
          (br_if $ady (i32.ge_u (local.get $y) (i32.const 8)))
          (local.set $b (local.get $a))
          (local.set $x (i32.const 0))
          (block $adx (loop $alx
            (br_if $adx (i32.ge_u (local.get $x) (i32.const 8)))
            (local.set $q (i32.add (select (i32.load offset=16 (local.get $pp)) (i32.load (local.get $b)) (i32.eq (local.get $mode) (i32.const 2)))
                                   (select (i32.load offset=3968 (local.get $i)) (i32.const 0) (local.get $nz))))
            (local.set $q (select (local.get $lo) (local.get $q) (i32.lt_s (local.get $q) (local.get $lo))))
            (i32.store (local.get $b) (select (local.get $hi) (local.get $q) (i32.gt_s (local.get $q) (local.get $hi))))
            (local.set $b (i32.add (local.get $b) (local.get $P4)))
            (local.set $i (i32.add (local.get $i) (i32.const 4)))
            (local.set $x (i32.add (local.get $x) (i32.const 1)))
            (br $alx)))
          (local.set $a (i32.add (local.get $a) (local.get $ostride)))
          (local.set $y (i32.add (local.get $y) (i32.const 1)))
          (br $aly)))
        (local.set $p (i32.add (local.get $p) (i32.const 1)))
        (br $ploop)))
      (local.set $t (i32.add (local.get $t) (i32.const 1)))
      (br $tloop))))
)
