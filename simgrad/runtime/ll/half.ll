; f16 <-> f32 conversions for x86 CPUs without F16C (runtime/half.py says why). No parameters.

define float @__extendhfsf2(half %h) {
  %b16 = bitcast half %h to i16
  %b = zext i16 %b16 to i32
  %s1 = and i32 %b, 32768
  %sign = shl i32 %s1, 16
  %e1 = lshr i32 %b, 10
  %exp = and i32 %e1, 31
  %man = and i32 %b, 1023
  %mant = shl i32 %man, 13
  ; normal: rebias the exponent (127 - 15 = 112)
  %e2 = add i32 %exp, 112
  %e3 = shl i32 %e2, 23
  %norm = or i32 %e3, %mant
  ; inf / NaN
  %special = or i32 %mant, 2139095040
  ; zero / subnormal: man * 2**-24, exact in f32
  %mf = uitofp i32 %man to float
  %sub = fmul float %mf, 0x3E70000000000000
  %subb = bitcast float %sub to i32
  %is_max = icmp eq i32 %exp, 31
  %is_zero = icmp eq i32 %exp, 0
  %r1 = select i1 %is_max, i32 %special, i32 %norm
  %r2 = select i1 %is_zero, i32 %subb, i32 %r1
  %r3 = or i32 %r2, %sign
  %f = bitcast i32 %r3 to float
  ret float %f
}

define half @__truncsfhf2(float %f) {
  %b = bitcast float %f to i32
  %s1 = lshr i32 %b, 16
  %sign = and i32 %s1, 32768
  %a = and i32 %b, 2147483647
  ; normal half: rebias by 112 << 23 and round the 13 dropped bits to nearest even
  %m = sub i32 %a, 939524096
  %lsb1 = lshr i32 %m, 13
  %lsb = and i32 %lsb1, 1
  %bias = add i32 %lsb, 4095
  %mr = add i32 %m, %bias
  %norm = lshr i32 %mr, 13
  ; subnormal half: round(mantissa-with-one >> (126 - exp)), zero when the shift exceeds 24
  %e = lshr i32 %a, 23
  %frac = and i32 %a, 8388607
  %one = or i32 %frac, 8388608
  %sh = sub i32 126, %e
  %big = icmp ugt i32 %sh, 24
  %shc = select i1 %big, i32 24, i32 %sh
  %q = lshr i32 %one, %shc
  %hbit = sub i32 %shc, 1
  %half = shl i32 1, %hbit
  %mask = sub i32 %half, 1
  %mask2 = or i32 %mask, %half
  %r = and i32 %one, %mask2
  %gt = icmp ugt i32 %r, %half
  %tie = icmp eq i32 %r, %half
  %qodd = trunc i32 %q to i1
  %tieup = and i1 %tie, %qodd
  %up = or i1 %gt, %tieup
  %upi = zext i1 %up to i32
  %sub0 = add i32 %q, %upi
  %sub = select i1 %big, i32 0, i32 %sub0
  ; pick: NaN, overflow to inf (>= 65520), normal (>= 2**-14), subnormal
  %is_nan = icmp ugt i32 %a, 2139095040
  %is_inf = icmp uge i32 %a, 1199566848
  %is_norm = icmp uge i32 %a, 947912704
  %v1 = select i1 %is_norm, i32 %norm, i32 %sub
  %v2 = select i1 %is_inf, i32 31744, i32 %v1
  %v3 = select i1 %is_nan, i32 32256, i32 %v2
  %v4 = or i32 %v3, %sign
  %v16 = trunc i32 %v4 to i16
  %h = bitcast i16 %v16 to half
  ret half %h
}
