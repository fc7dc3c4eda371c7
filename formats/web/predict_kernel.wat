;; predict_kernel.wat — the browser viewer's view prediction (lfc.js TxDecoder._predictTb: each
;; 8×8 transform block of a view as the weighted sum of its key views' bilinear taps, in 1/16 px)
;; as WebAssembly with 128-bit SIMD, four plane samples at a time. Built into predict_kernel.js
;; (base64) by tools/build_kernels.mjs with wabt; lfc.js keeps the loops where WebAssembly SIMD
;; is missing. Integer arithmetic in _predictTb's order (every value fits 32 bits): the same
;; planes, bit for bit (tests/formats/test_web_decoder.py). Written inline (no helper calls:
;; Node 20's V8 does not inline WebAssembly calls).
;;
;; Memory: the accumulator at byte 64 (64·P int32), a window's clamped copy at byte 2048
;; (9·9·P int32), the caller's table, views and key planes above 4096.
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
      (br $rloop)))))
