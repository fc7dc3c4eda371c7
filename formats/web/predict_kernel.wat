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
;; per plane [step16, bypass, lo, hi, flat] (int32) at 5248; the scan's context bands (64 int32)
;; at 5344 and the planes' classes (P int32) at 5600; the caller's tables, views and key planes
;; from 8192.
;;
;; A block stream's parse (lfc.js parseBlock: rANS symbols, then raw bits from the stream's end)
;; the same way, symbol for symbol, with the same checks in the same order (an error code for
;; each of parseBlock's messages).
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

  (global $x (mut i32) (i32.const 0))      ;; the rANS state
  (global $q (mut i32) (i32.const 0))      ;; the next byte's address
  (global $e (mut i32) (i32.const 0))      ;; the stream's end
  (global $bad (mut i32) (i32.const 0))    ;; set where a symbol read past the end
  (global $slot (mut i32) (i32.const 0))
  (global $freq (mut i32) (i32.const 0))
  (global $cum (mut i32) (i32.const 0))
  (global $A (mut i32) (i32.const 0))
  ;; one symbol of context `ctx` (lfc.js Rans.get); 255 with $bad set where it reads past the end
  (func $get (param $ctx i32) (result i32)
    (local $x i32) (local $sl i32) (local $s i32)
    (local.set $x (global.get $x))
    (local.set $sl (i32.and (local.get $x) (i32.const 4095)))
    (local.set $s (i32.load8_u (i32.add (global.get $slot) (i32.add (i32.shl (local.get $ctx) (i32.const 12)) (local.get $sl)))))
    (local.set $x (i32.sub (i32.add (i32.mul (i32.load (i32.add (global.get $freq) (i32.shl (i32.add (i32.mul (local.get $ctx) (global.get $A)) (local.get $s)) (i32.const 2))))
                                             (i32.shr_u (local.get $x) (i32.const 12)))
                                    (local.get $sl))
                           (i32.load (i32.add (global.get $cum) (i32.shl (i32.add (i32.mul (local.get $ctx) (i32.add (global.get $A) (i32.const 1))) (local.get $s)) (i32.const 2))))))
    (block $ok (loop $renorm
      (br_if $ok (i32.ge_u (local.get $x) (i32.const 32768)))
      (if (i32.ge_u (global.get $q) (global.get $e)) (then
        (global.set $bad (i32.const 1))
        (global.set $x (local.get $x))
        (return (i32.const 255))))
      (local.set $x (i32.or (i32.shl (local.get $x) (i32.const 8)) (i32.load8_u (global.get $q))))
      (global.set $q (i32.add (global.get $q) (i32.const 1)))
      (br $renorm)))
    (global.set $x (local.get $x))
    (local.get $s))
  ;; bit i of the raw bits: the first kb from the state's remainder R, then the bytes from raw
  (func $bit (param $i i32) (param $R i32) (param $kb i32) (param $raw i32) (result i32)
    (if (result i32) (i32.lt_u (local.get $i) (local.get $kb))
      (then (i32.and (i32.shr_u (local.get $R) (local.get $i)) (i32.const 1)))
      (else
        (local.set $i (i32.sub (local.get $i) (local.get $kb)))
        (i32.and (i32.shr_u (i32.load8_u (i32.add (local.get $raw) (i32.shr_u (local.get $i) (i32.const 3))))
                            (i32.and (local.get $i) (i32.const 7))) (i32.const 1)))))
  ;; parse the stream at bytes [a, b) of `nt` tbs of P planes → modes (int32 nt) and levels (int32
  ;; nt·P·64, zeroed by the caller), with scratch `last` (nt·P int32), `rec` and `esc` (nt·P·64
  ;; int32 each); the tables: slot (uint8 C·4096), freq (int32 C·A), cum (int32 C·(A+1)).
  ;; Returns 0, or parseBlock's error: 1 a stream shorter than its state, 2 a read past its end,
  ;; 3 a tb mode, 4 a last position, 5 a magnitude symbol, 6 an escape bucket, 7 the raw bits.
  (func (export "parse") (param $a i32) (param $b i32) (param $nt i32) (param $P i32) (param $kind i32) (param $key i32)
                         (param $lev i32) (param $modes i32) (param $last i32) (param $rec i32) (param $esc i32)
                         (param $slot i32) (param $freq i32) (param $cum i32) (param $A i32) (result i32)
    (local $t i32) (local $s i32) (local $prev i32) (local $p i32) (local $g i32) (local $n i32) (local $base i32)
    (local $pos i32) (local $h1 i32) (local $h2 i32) (local $nc i32) (local $ne i32) (local $i i32) (local $c i32)
    (local $k i32) (local $nbits i32) (local $kb i32) (local $raw i32) (local $R i32) (local $r i32) (local $j i32) (local $at i32)
    (if (i32.lt_s (i32.sub (local.get $b) (local.get $a)) (i32.const 3)) (then (return (i32.const 1))))
    (global.set $slot (local.get $slot))
    (global.set $freq (local.get $freq))
    (global.set $cum (local.get $cum))
    (global.set $A (local.get $A))
    (global.set $x (i32.or (i32.or (i32.load8_u (local.get $a)) (i32.shl (i32.load8_u offset=1 (local.get $a)) (i32.const 8)))
                           (i32.shl (i32.load8_u offset=2 (local.get $a)) (i32.const 16))))
    (global.set $q (i32.add (local.get $a) (i32.const 3)))
    (global.set $e (local.get $b))
    (global.set $bad (i32.const 0))
    ;; the tbs' modes
    (local.set $prev (i32.const 3))
    (local.set $t (i32.const 0))
    (block $mdone (loop $mloop
      (br_if $mdone (i32.ge_s (local.get $t) (local.get $nt)))
      (local.set $s (call $get (i32.add (i32.shl (local.get $kind) (i32.const 2)) (local.get $prev))))
      (if (i32.ge_u (local.get $s) (i32.const 3)) (then (return (select (i32.const 2) (i32.const 3) (global.get $bad)))))
      (i32.store (i32.add (local.get $modes) (i32.shl (local.get $t) (i32.const 2))) (local.get $s))
      (local.set $prev (local.get $s))
      (local.set $t (i32.add (local.get $t) (i32.const 1)))
      (br $mloop)))
    ;; each coded tb's last positions, per plane
    (local.set $t (i32.const 0))
    (block $ldone (loop $lloop
      (br_if $ldone (i32.ge_s (local.get $t) (local.get $nt)))
      (local.set $c (i32.load (i32.add (local.get $modes) (i32.shl (local.get $t) (i32.const 2)))))
      (local.set $p (i32.const 0))
      (block $lpdone (loop $lploop
        (br_if $lpdone (i32.ge_s (local.get $p) (local.get $P)))
        (local.set $s (i32.const 0))
        (if (local.get $c) (then
          (local.set $s (call $get (i32.add (i32.const 8) (i32.add (i32.shl (i32.add (i32.shl (i32.load offset=5600 (i32.shl (local.get $p) (i32.const 2))) (i32.const 1))
                                                                                     (i32.eq (local.get $c) (i32.const 2))) (i32.const 1))
                                                                (local.get $key)))))
          (if (i32.gt_u (local.get $s) (i32.const 64)) (then (return (select (i32.const 2) (i32.const 4) (global.get $bad)))))))
        (i32.store (i32.add (local.get $last) (i32.shl (i32.add (i32.mul (local.get $t) (local.get $P)) (local.get $p)) (i32.const 2))) (local.get $s))
        (local.set $p (i32.add (local.get $p) (i32.const 1)))
        (br $lploop)))
      (local.set $t (i32.add (local.get $t) (i32.const 1)))
      (br $lloop)))
    ;; magnitudes, from each group's last position down; every nonzero one recorded (index·2 + first)
    (local.set $g (i32.const 0))
    (block $gdone (loop $gloop
      (br_if $gdone (i32.ge_s (local.get $g) (i32.mul (local.get $nt) (local.get $P))))
      (local.set $n (i32.load (i32.add (local.get $last) (i32.shl (local.get $g) (i32.const 2)))))
      (if (local.get $n) (then
        (local.set $base (i32.add (i32.add (i32.const 20) (i32.mul (i32.load offset=5600 (i32.shl (i32.rem_u (local.get $g) (local.get $P)) (i32.const 2))) (i32.const 48)))
                                  (i32.shl (local.get $key) (i32.const 2))))
        (local.set $pos (i32.sub (local.get $n) (i32.const 1)))
        (local.set $s (call $get (i32.add (local.get $base) (i32.load offset=5344 (i32.shl (local.get $pos) (i32.const 2))))))
        (if (i32.gt_u (local.get $s) (i32.const 15)) (then (return (select (i32.const 2) (i32.const 5) (global.get $bad)))))
        (local.set $at (i32.add (i32.shl (local.get $g) (i32.const 6)) (local.get $pos)))
        (i32.store (i32.add (local.get $lev) (i32.shl (local.get $at) (i32.const 2))) (i32.add (local.get $s) (i32.const 1)))
        (i32.store (i32.add (local.get $rec) (i32.shl (local.get $nc) (i32.const 2))) (i32.or (i32.shl (local.get $at) (i32.const 1)) (i32.const 1)))
        (local.set $nc (i32.add (local.get $nc) (i32.const 1)))
        (local.set $h1 (i32.add (local.get $s) (i32.const 1)))
        (local.set $h2 (i32.const 0))
        (block $pdone (loop $ploop
          (local.set $pos (i32.sub (local.get $pos) (i32.const 1)))
          (br_if $pdone (i32.lt_s (local.get $pos) (i32.const 0)))
          (local.set $s (call $get (i32.add (i32.add (i32.add (local.get $base) (i32.load offset=5344 (i32.shl (local.get $pos) (i32.const 2))))
                                                     (i32.const 1))
                                            (i32.add (i32.ne (local.get $h1) (i32.const 0)) (i32.ne (local.get $h2) (i32.const 0))))))
          (if (i32.gt_u (local.get $s) (i32.const 15)) (then (return (select (i32.const 2) (i32.const 5) (global.get $bad)))))
          (local.set $h2 (local.get $h1))
          (local.set $h1 (local.get $s))
          (if (local.get $s) (then
            (local.set $at (i32.add (i32.shl (local.get $g) (i32.const 6)) (local.get $pos)))
            (i32.store (i32.add (local.get $lev) (i32.shl (local.get $at) (i32.const 2))) (local.get $s))
            (i32.store (i32.add (local.get $rec) (i32.shl (local.get $nc) (i32.const 2))) (i32.shl (local.get $at) (i32.const 1)))
            (local.set $nc (i32.add (local.get $nc) (i32.const 1)))))
          (br $ploop)))))
      (local.set $g (i32.add (local.get $g) (i32.const 1)))
      (br $gloop)))
    ;; escapes' buckets, in the recorded order (each kept as record·32 + bucket)
    (local.set $nbits (local.get $nc))
    (local.set $i (i32.const 0))
    (block $edone (loop $eloop
      (br_if $edone (i32.ge_s (local.get $i) (local.get $nc)))
      (local.set $c (i32.load (i32.add (local.get $rec) (i32.shl (local.get $i) (i32.const 2)))))
      (local.set $at (i32.shr_u (local.get $c) (i32.const 1)))
      (if (i32.eq (i32.sub (i32.load (i32.add (local.get $lev) (i32.shl (local.get $at) (i32.const 2)))) (i32.and (local.get $c) (i32.const 1)))
                  (i32.const 15)) (then
        (local.set $k (call $get (i32.add (i32.const 164) (i32.load offset=5600 (i32.shl (i32.rem_u (i32.shr_u (local.get $at) (i32.const 6)) (local.get $P)) (i32.const 2))))))
        (if (i32.ge_u (local.get $k) (i32.const 24)) (then (return (select (i32.const 2) (i32.const 6) (global.get $bad)))))
        (i32.store (i32.add (local.get $esc) (i32.shl (local.get $ne) (i32.const 2))) (i32.or (i32.shl (local.get $i) (i32.const 5)) (local.get $k)))
        (local.set $ne (i32.add (local.get $ne) (i32.const 1)))
        (local.set $nbits (i32.add (local.get $nbits) (local.get $k)))))
      (local.set $i (i32.add (local.get $i) (i32.const 1)))
      (br $eloop)))
    ;; the raw bits: the last kb of them in the final state, the others before the stream's end
    (local.set $kb (select (local.get $nbits) (i32.const 15) (i32.lt_s (local.get $nbits) (i32.const 15))))
    (local.set $raw (i32.sub (local.get $b) (i32.shr_u (i32.add (i32.sub (local.get $nbits) (local.get $kb)) (i32.const 7)) (i32.const 3))))
    (local.set $R (i32.sub (global.get $x) (i32.const 32768)))
    (if (i32.or (i32.or (i32.lt_s (local.get $raw) (global.get $q)) (i32.ne (global.get $q) (local.get $raw)))
                (i32.or (i32.lt_s (local.get $R) (i32.const 0)) (i32.ge_s (local.get $R) (i32.shl (i32.const 1) (local.get $kb)))))
      (then (return (i32.const 7))))
    ;; the escapes' suffixes (after every sign), then the signs
    (local.set $r (local.get $nc))               ;; the next suffix bit
    (local.set $j (i32.const 0))
    (block $sdone (loop $sloop
      (br_if $sdone (i32.ge_s (local.get $j) (local.get $ne)))
      (local.set $c (i32.load (i32.add (local.get $esc) (i32.shl (local.get $j) (i32.const 2)))))
      (local.set $k (i32.and (local.get $c) (i32.const 31)))
      (local.set $s (i32.const 0))
      (local.set $p (i32.const 0))
      (block $bdone (loop $bloop
        (br_if $bdone (i32.ge_s (local.get $p) (local.get $k)))
        (local.set $s (i32.or (local.get $s) (i32.shl (call $bit (local.get $r) (local.get $R) (local.get $kb) (local.get $raw)) (local.get $p))))
        (local.set $r (i32.add (local.get $r) (i32.const 1)))
        (local.set $p (i32.add (local.get $p) (i32.const 1)))
        (br $bloop)))
      (local.set $c (i32.load (i32.add (local.get $rec) (i32.shl (i32.shr_u (local.get $c) (i32.const 5)) (i32.const 2)))))
      (i32.store (i32.add (local.get $lev) (i32.shl (i32.shr_u (local.get $c) (i32.const 1)) (i32.const 2)))
        (i32.add (i32.add (i32.add (i32.const 15) (i32.and (local.get $c) (i32.const 1))) (i32.sub (i32.shl (i32.const 1) (local.get $k)) (i32.const 1))) (local.get $s)))
      (local.set $j (i32.add (local.get $j) (i32.const 1)))
      (br $sloop)))
    (local.set $i (i32.const 0))
    (block $ndone (loop $nloop
      (br_if $ndone (i32.ge_s (local.get $i) (local.get $nc)))
      (if (call $bit (local.get $i) (local.get $R) (local.get $kb) (local.get $raw)) (then
        (local.set $at (i32.add (local.get $lev) (i32.shl (i32.shr_u (i32.load (i32.add (local.get $rec) (i32.shl (local.get $i) (i32.const 2)))) (i32.const 1)) (i32.const 2))))
        (i32.store (local.get $at) (i32.sub (i32.const 0) (i32.load (local.get $at))))))
      (local.set $i (i32.add (local.get $i) (i32.const 1)))
      (br $nloop)))
    (i32.const 0))
)
