declare noalias ptr @calloc(i64, i64)
!0 = !{}
define internal void @sg_kernel_task1(ptr %clo, i64 %lo, i64 %hi, i32 %tid) {
entry:
  %ctx = load ptr, ptr %clo
  %lo.1 = trunc i64 %lo to i32
  %hi.2 = trunc i64 %hi to i32
  %red.3 = alloca float
  store float 0x0000000000000000, ptr %red.3
  %cp.16 = getelementptr i64, ptr %ctx, i64 0
  %cv.17 = load ptr, ptr %cp.16
  %rp.18 = getelementptr ptr, ptr %cv.17, i64 0
  %root.19 = load ptr, ptr %rp.18, !invariant.load !0
  %cp.41 = getelementptr i64, ptr %ctx, i64 0
  %cv.42 = load ptr, ptr %cp.41
  %rp.43 = getelementptr ptr, ptr %cv.42, i64 1
  %root.44 = load ptr, ptr %rp.43, !invariant.load !0
  %cp.47 = getelementptr i64, ptr %ctx, i64 0
  %cv.48 = load ptr, ptr %cp.47
  %rp.49 = getelementptr ptr, ptr %cv.48, i64 2
  %root.50 = load ptr, ptr %rp.49, !invariant.load !0
  br label %pre.4
pre.4:
  br label %head.5
head.5:
  %i.9 = phi i32 [%lo.1, %pre.4], [%inext.10, %latch.7]
  %c.11 = icmp slt i32 %i.9, %hi.2
  br i1 %c.11, label %body.6, label %done.8
body.6:
  %v.12 = and i32 %i.9, 7
  %cv.13 = sext i32 %v.12 to i64
  %v.14 = mul nuw nsw i64 %cv.13, 8
  %ptr.15 = getelementptr inbounds i8, ptr %root.19, i64 %v.14
  %cv.20 = sext i32 %v.12 to i64
  %v.21 = mul nuw nsw i64 %cv.20, 8
  %v.22 = add nuw nsw i64 4, %v.21
  %ptr.23 = getelementptr inbounds i8, ptr %root.19, i64 %v.14
  %pv.24 = insertelement <2 x float> poison, float 0x3FF0000000000000, i32 0
  %pv.25 = insertelement <2 x float> %pv.24, float 0x4000000000000000, i32 1
  %pinc.26 = bitcast <2 x float> %pv.25 to i64
  %cur.30 = load atomic i64, ptr %ptr.23 monotonic, align 8
  br label %cas.27
cas.27:
  br label %casloop.28
casloop.28:
  %c.31 = phi i64 [%cur.30, %cas.27], [%c.36, %casloop.28]
  %c.32 = bitcast i64 %c.31 to <2 x float>
  %c.34 = fadd <2 x float> %c.32, %pv.25
  %c.33 = bitcast <2 x float> %c.34 to i64
  %c.35 = cmpxchg ptr %ptr.23, i64 %c.31, i64 %c.33 monotonic monotonic, align 8
  %c.36 = extractvalue { i64, i1 } %c.35, 0
  %c.37 = extractvalue { i64, i1 } %c.35, 1
  br i1 %c.37, label %casdone.29, label %casloop.28
casdone.29:
  %cv.38 = sext i32 %v.12 to i64
  %v.39 = mul nuw nsw i64 %cv.38, 4
  %ptr.40 = getelementptr inbounds i8, ptr %root.44, i64 %v.39
  %old.45 = atomicrmw fadd ptr %ptr.40, float 0x3FF0000000000000 monotonic
  %ptr.46 = getelementptr inbounds i8, ptr %root.50, i64 0
  %old.51 = load float, ptr %red.3
  %new.52 = fadd nsz float %old.51, 0x3FF0000000000000
  store float %new.52, ptr %red.3
  br label %latch.7
latch.7:
  %inext.10 = add i32 %i.9, 1
  br label %head.5
done.8:
  %sum.53 = load float, ptr %red.3
  %ptr.54 = getelementptr inbounds i8, ptr %root.50, i64 0
  %old.55 = atomicrmw fadd ptr %ptr.54, float %sum.53 monotonic
  ret void
}
define internal void @sg_kernel_task1_private(ptr %clo, i64 %lo, i64 %hi, i32 %tid) {
entry:
  %ctx = load ptr, ptr %clo
  %pr.1 = getelementptr i64, ptr %clo, i64 1
  %pr.2 = load ptr, ptr %pr.1
  %pr.3 = zext i32 %tid to i64
  %pr.4 = mul i64 %pr.3, 64
  %pr.5 = getelementptr inbounds i8, ptr %pr.2, i64 %pr.4
  %pr.7 = sub i64 0, 0
  %pr.6 = getelementptr i8, ptr %pr.5, i64 %pr.7
  %pr.8 = getelementptr i64, ptr %clo, i64 2
  %pr.9 = load ptr, ptr %pr.8
  %pr.10 = zext i32 %tid to i64
  %pr.11 = mul i64 %pr.10, 32
  %pr.12 = getelementptr inbounds i8, ptr %pr.9, i64 %pr.11
  %pr.14 = sub i64 0, 0
  %pr.13 = getelementptr i8, ptr %pr.12, i64 %pr.14
  %lo.15 = trunc i64 %lo to i32
  %hi.16 = trunc i64 %hi to i32
  %red.17 = alloca float
  store float 0x0000000000000000, ptr %red.17
  %cp.44 = getelementptr i64, ptr %ctx, i64 0
  %cv.45 = load ptr, ptr %cp.44
  %rp.46 = getelementptr ptr, ptr %cv.45, i64 2
  %root.47 = load ptr, ptr %rp.46, !invariant.load !0
  br label %pre.18
pre.18:
  br label %head.19
head.19:
  %i.23 = phi i32 [%lo.15, %pre.18], [%inext.24, %latch.21]
  %c.25 = icmp slt i32 %i.23, %hi.16
  br i1 %c.25, label %body.20, label %done.22
body.20:
  %v.26 = and i32 %i.23, 7
  %cv.27 = sext i32 %v.26 to i64
  %v.28 = mul nuw nsw i64 %cv.27, 8
  %ptr.29 = getelementptr i8, ptr %pr.6, i64 %v.28
  %old.30 = load float, ptr %ptr.29
  %new.31 = fadd nsz float %old.30, 0x3FF0000000000000
  store float %new.31, ptr %ptr.29
  %cv.32 = sext i32 %v.26 to i64
  %v.33 = mul nuw nsw i64 %cv.32, 8
  %v.34 = add nuw nsw i64 4, %v.33
  %ptr.35 = getelementptr i8, ptr %pr.6, i64 %v.34
  %old.36 = load float, ptr %ptr.35
  %new.37 = fadd nsz float %old.36, 0x4000000000000000
  store float %new.37, ptr %ptr.35
  %cv.38 = sext i32 %v.26 to i64
  %v.39 = mul nuw nsw i64 %cv.38, 4
  %ptr.40 = getelementptr i8, ptr %pr.13, i64 %v.39
  %old.41 = load float, ptr %ptr.40
  %new.42 = fadd nsz float %old.41, 0x3FF0000000000000
  store float %new.42, ptr %ptr.40
  %ptr.43 = getelementptr inbounds i8, ptr %root.47, i64 0
  %old.48 = load float, ptr %red.17
  %new.49 = fadd nsz float %old.48, 0x3FF0000000000000
  store float %new.49, ptr %red.17
  br label %latch.21
latch.21:
  %inext.24 = add i32 %i.23, 1
  br label %head.19
done.22:
  %sum.50 = load float, ptr %red.17
  %ptr.51 = getelementptr inbounds i8, ptr %root.47, i64 0
  %old.52 = atomicrmw fadd ptr %ptr.51, float %sum.50 monotonic
  ret void
}
define internal void @sg_kernel_task1_private_sum0(ptr %clo, i64 %lo, i64 %hi, i32 %tid) {
entry:
  %buf = load ptr, ptr %clo
  %realp = getelementptr i64, ptr %clo, i64 1
  %real = load ptr, ptr %realp
  %ntp = getelementptr i64, ptr %clo, i64 2
  %nt = load i64, ptr %ntp
  br label %thead
thead:
  %t = phi i64 [0, %entry], [%tnext, %kdone]
  %tc = icmp slt i64 %t, %nt
  br i1 %tc, label %tbody, label %done
tbody:
  %base = mul i64 %t, 16
  %copy = getelementptr inbounds float, ptr %buf, i64 %base
  br label %khead
khead:
  %k = phi i64 [%lo, %tbody], [%knext, %kbody]
  %kc = icmp slt i64 %k, %hi
  br i1 %kc, label %kbody, label %kdone
kbody:
  %src = getelementptr inbounds float, ptr %copy, i64 %k
  %dst = getelementptr inbounds float, ptr %real, i64 %k
  %part = load float, ptr %src
  %old = load float, ptr %dst
  %added = fadd float %old, %part
  %zero = fcmp oeq float %part, 0.0
  %new = select i1 %zero, float %old, float %added
  store float 0.0, ptr %src
  store float %new, ptr %dst
  %knext = add i64 %k, 1
  br label %khead
kdone:
  %tnext = add i64 %t, 1
  br label %thead
done:
  ret void
}
define internal void @sg_kernel_task1_private_sum1(ptr %clo, i64 %lo, i64 %hi, i32 %tid) {
entry:
  %buf = load ptr, ptr %clo
  %realp = getelementptr i64, ptr %clo, i64 1
  %real = load ptr, ptr %realp
  %ntp = getelementptr i64, ptr %clo, i64 2
  %nt = load i64, ptr %ntp
  br label %thead
thead:
  %t = phi i64 [0, %entry], [%tnext, %kdone]
  %tc = icmp slt i64 %t, %nt
  br i1 %tc, label %tbody, label %done
tbody:
  %base = mul i64 %t, 8
  %copy = getelementptr inbounds float, ptr %buf, i64 %base
  br label %khead
khead:
  %k = phi i64 [%lo, %tbody], [%knext, %kbody]
  %kc = icmp slt i64 %k, %hi
  br i1 %kc, label %kbody, label %kdone
kbody:
  %src = getelementptr inbounds float, ptr %copy, i64 %k
  %dst = getelementptr inbounds float, ptr %real, i64 %k
  %part = load float, ptr %src
  %old = load float, ptr %dst
  %added = fadd float %old, %part
  %zero = fcmp oeq float %part, 0.0
  %new = select i1 %zero, float %old, float %added
  store float 0.0, ptr %src
  store float %new, ptr %dst
  %knext = add i64 %k, 1
  br label %khead
kdone:
  %tnext = add i64 %t, 1
  br label %thead
done:
  ret void
}
define void @sg_kernel(ptr %ctx) {
entry:
  %cp.1 = getelementptr i64, ptr %ctx, i64 8
  %cv.2 = load ptr, ptr %cp.1
  store atomic i32 0, ptr %cv.2 monotonic, align 4
  %clo.3 = alloca [3 x i64], align 8
  %cp.6 = getelementptr i64, ptr %ctx, i64 3
  %cv.7 = load ptr, ptr %cp.6
  %cp.8 = getelementptr i64, ptr %ctx, i64 7
  %cv.9 = load i64, ptr %cp.8
  %cp.24 = getelementptr i64, ptr %ctx, i64 0
  %cv.25 = load ptr, ptr %cp.24
  %rp.26 = getelementptr ptr, ptr %cv.25, i64 0
  %root.27 = load ptr, ptr %rp.26, !invariant.load !0
  %cp.31 = getelementptr i64, ptr %ctx, i64 0
  %cv.32 = load ptr, ptr %cp.31
  %rp.33 = getelementptr ptr, ptr %cv.32, i64 1
  %root.34 = load ptr, ptr %rp.33, !invariant.load !0
  %sclo.64 = alloca [3 x i64], align 8
  %sclo.70 = alloca [3 x i64], align 8
  store ptr %ctx, ptr %clo.3
  %b.4 = sext i32 0 to i64
  %e.5 = sext i32 64 to i64
  %pv.10 = sub i64 %e.5, %b.4
  %pv.16 = icmp sle i64 %cv.9, 1
  %pv.17 = icmp sle i64 %pv.10, 455
  %pv.18 = or i1 %pv.16, %pv.17
  br i1 %pv.18, label %direct.19, label %decide.20
direct.19:
  %pslot.21 = getelementptr i64, ptr %clo.3, i64 1
  %real.23 = getelementptr i8, ptr %root.27, i64 0
  %real.22 = getelementptr i8, ptr %real.23, i64 0
  store ptr %real.22, ptr %pslot.21
  %pslot.28 = getelementptr i64, ptr %clo.3, i64 2
  %real.30 = getelementptr i8, ptr %root.34, i64 0
  %real.29 = getelementptr i8, ptr %real.30, i64 0
  store ptr %real.29, ptr %pslot.28
  call void %cv.7(ptr @sg_kernel_task1_private, ptr %clo.3, i64 %b.4, i64 %e.5, i64 455)
  br label %scatterdone.35
decide.20:
  %pv.11 = mul i64 %pv.10, 24
  %pv.12 = mul i64 %cv.9, 24
  %pv.13 = icmp sge i64 %pv.11, %pv.12
  %pv.14 = icmp sgt i64 %cv.9, 1
  %pv.36 = mul i64 %cv.9, 96
  %pv.37 = icmp ule i64 %pv.36, 268435456
  %pv.38 = and i1 %pv.13, %pv.14
  %pv.15 = and i1 %pv.38, %pv.37
  br i1 %pv.15, label %alloc.40, label %atomic.39
alloc.40:
  %pctx.42 = getelementptr i64, ptr %ctx, i64 11
  %phave.43 = load ptr, ptr %pctx.42
  %pnull.46 = icmp eq ptr %phave.43, null
  br i1 %pnull.46, label %pfresh.44, label %pready.45
pfresh.44:
  %pnew.47 = call ptr @calloc(i64 %cv.9, i64 64)
  store ptr %pnew.47, ptr %pctx.42
  br label %pready.45
pready.45:
  %priv.48 = load ptr, ptr %pctx.42
  %pslot.49 = getelementptr i64, ptr %clo.3, i64 1
  store ptr %priv.48, ptr %pslot.49
  %pnn.50 = icmp ne ptr %priv.48, null
  %pok.51 = and i1 true, %pnn.50
  %pctx.52 = getelementptr i64, ptr %ctx, i64 12
  %phave.53 = load ptr, ptr %pctx.52
  %pnull.56 = icmp eq ptr %phave.53, null
  br i1 %pnull.56, label %pfresh.54, label %pready.55
pfresh.54:
  %pnew.57 = call ptr @calloc(i64 %cv.9, i64 32)
  store ptr %pnew.57, ptr %pctx.52
  br label %pready.55
pready.55:
  %priv.58 = load ptr, ptr %pctx.52
  %pslot.59 = getelementptr i64, ptr %clo.3, i64 2
  store ptr %priv.58, ptr %pslot.59
  %pnn.60 = icmp ne ptr %priv.58, null
  %pok.61 = and i1 %pok.51, %pnn.60
  br i1 %pok.61, label %private.41, label %atomic.39
private.41:
  call void %cv.7(ptr @sg_kernel_task1_private, ptr %clo.3, i64 %b.4, i64 %e.5, i64 455)
  %real.63 = getelementptr i8, ptr %root.27, i64 0
  %real.62 = getelementptr i8, ptr %real.63, i64 0
  %sslot.65 = getelementptr i64, ptr %sclo.64, i64 0
  store ptr %priv.48, ptr %sslot.65
  %sslot.66 = getelementptr i64, ptr %sclo.64, i64 1
  store ptr %real.62, ptr %sslot.66
  %sslot.67 = getelementptr i64, ptr %sclo.64, i64 2
  store i64 %cv.9, ptr %sslot.67
  call void %cv.7(ptr @sg_kernel_task1_private_sum0, ptr %sclo.64, i64 0, i64 16, i64 8192)
  %real.69 = getelementptr i8, ptr %root.34, i64 0
  %real.68 = getelementptr i8, ptr %real.69, i64 0
  %sslot.71 = getelementptr i64, ptr %sclo.70, i64 0
  store ptr %priv.58, ptr %sslot.71
  %sslot.72 = getelementptr i64, ptr %sclo.70, i64 1
  store ptr %real.68, ptr %sslot.72
  %sslot.73 = getelementptr i64, ptr %sclo.70, i64 2
  store i64 %cv.9, ptr %sslot.73
  call void %cv.7(ptr @sg_kernel_task1_private_sum1, ptr %sclo.70, i64 0, i64 8, i64 8192)
  br label %scatterdone.35
atomic.39:
  call void %cv.7(ptr @sg_kernel_task1, ptr %clo.3, i64 %b.4, i64 %e.5, i64 455)
  br label %scatterdone.35
scatterdone.35:
  %cancel.74 = load atomic i32, ptr %cv.2 monotonic, align 4
  %cancelled.75 = icmp ne i32 %cancel.74, 0
  br i1 %cancelled.75, label %stop.76, label %go.77
stop.76:
  call void @sg_report(ptr %ctx, i64 -1, i64 0)
  ret void
go.77:
  ret void
}

define internal void @sg_report(ptr %ctx, i64 %code, i64 %value) noinline {
  %ep = getelementptr i64, ptr %ctx, i64 1
  %err = load ptr, ptr %ep
  %r = cmpxchg ptr %err, i64 0, i64 %code monotonic monotonic
  %ok = extractvalue { i64, i1 } %r, 1
  br i1 %ok, label %store, label %done
store:
  %vp = getelementptr i64, ptr %err, i64 1
  store i64 %value, ptr %vp
  br label %done
done:
  ret void
}

define internal i32 @sg_rand_u32(ptr %ctx, i32 %tid) {
  %rp = getelementptr i64, ptr %ctx, i64 2
  %base = load ptr, ptr %rp
  %off = mul i32 %tid, 16
  %s = getelementptr i8, ptr %base, i32 %off
  %p1 = getelementptr i32, ptr %s, i32 1
  %p2 = getelementptr i32, ptr %s, i32 2
  %p3 = getelementptr i32, ptr %s, i32 3
  %x = load i32, ptr %s
  %y = load i32, ptr %p1
  %z = load i32, ptr %p2
  %w = load i32, ptr %p3
  %t0 = shl i32 %x, 11
  %t = xor i32 %x, %t0
  %t1 = lshr i32 %t, 8
  %t2 = xor i32 %t, %t1
  %w1 = lshr i32 %w, 19
  %w2 = xor i32 %w, %w1
  %n = xor i32 %w2, %t2
  store i32 %y, ptr %s
  store i32 %z, ptr %p1
  store i32 %w, ptr %p2
  store i32 %n, ptr %p3
  ret i32 %n
}

