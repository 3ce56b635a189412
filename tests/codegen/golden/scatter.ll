declare noalias ptr @calloc(i64, i64)
declare void @free(ptr)
!0 = !{}
!900000 = distinct !{!900000, !"simgrad fields"}
!900002 = distinct !{!900002, !900000, !"tree 0 byte 0"}
!900003 = !{!900002}
!900004 = !{!900005, !900008}
!900005 = distinct !{!900005, !900000, !"tree 0 byte 4"}
!900006 = !{!900005}
!900007 = !{!900002, !900008}
!900008 = distinct !{!900008, !900000, !"tree 1 byte 0"}
!900009 = !{!900008}
!900010 = !{!900002, !900005}
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
  %root.19 = load ptr, ptr %rp.18, !invariant.load !0, !dereferenceable !{i64 60}, !align !{i64 64}
  %cp.41 = getelementptr i64, ptr %ctx, i64 0
  %cv.42 = load ptr, ptr %cp.41
  %rp.43 = getelementptr ptr, ptr %cv.42, i64 1
  %root.44 = load ptr, ptr %rp.43, !invariant.load !0, !dereferenceable !{i64 32}, !align !{i64 64}
  %cp.47 = getelementptr i64, ptr %ctx, i64 0
  %cv.48 = load ptr, ptr %cp.47
  %rp.49 = getelementptr ptr, ptr %cv.48, i64 2
  %root.50 = load ptr, ptr %rp.49, !invariant.load !0, !dereferenceable !{i64 4}, !align !{i64 64}
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
  %root.47 = load ptr, ptr %rp.46, !invariant.load !0, !dereferenceable !{i64 4}, !align !{i64 64}
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
  %old.30 = load float, ptr %ptr.29, !alias.scope !900003, !noalias !900004
  %new.31 = fadd nsz float %old.30, 0x3FF0000000000000
  store float %new.31, ptr %ptr.29, !alias.scope !900003, !noalias !900004
  %cv.32 = sext i32 %v.26 to i64
  %v.33 = mul nuw nsw i64 %cv.32, 8
  %v.34 = add nuw nsw i64 4, %v.33
  %ptr.35 = getelementptr i8, ptr %pr.6, i64 %v.34
  %old.36 = load float, ptr %ptr.35, !alias.scope !900006, !noalias !900007
  %new.37 = fadd nsz float %old.36, 0x4000000000000000
  store float %new.37, ptr %ptr.35, !alias.scope !900006, !noalias !900007
  %cv.38 = sext i32 %v.26 to i64
  %v.39 = mul nuw nsw i64 %cv.38, 4
  %ptr.40 = getelementptr i8, ptr %pr.13, i64 %v.39
  %old.41 = load float, ptr %ptr.40, !alias.scope !900009, !noalias !900010
  %new.42 = fadd nsz float %old.41, 0x3FF0000000000000
  store float %new.42, ptr %ptr.40, !alias.scope !900009, !noalias !900010
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
  %cp.23 = getelementptr i64, ptr %ctx, i64 0
  %cv.24 = load ptr, ptr %cp.23
  %rp.25 = getelementptr ptr, ptr %cv.24, i64 0
  %root.26 = load ptr, ptr %rp.25, !invariant.load !0
  %cp.30 = getelementptr i64, ptr %ctx, i64 0
  %cv.31 = load ptr, ptr %cp.30
  %rp.32 = getelementptr ptr, ptr %cv.31, i64 1
  %root.33 = load ptr, ptr %rp.32, !invariant.load !0
  %sclo.74 = alloca [4 x i64], align 8
  %sclo.85 = alloca [4 x i64], align 8
  store ptr %ctx, ptr %clo.3
  %b.4 = sext i32 0 to i64
  %e.5 = sext i32 64 to i64
  %pv.14 = sub i64 %e.5, %b.4
  %pv.15 = icmp sle i64 %cv.9, 1
  %pv.16 = icmp sle i64 %pv.14, 455
  %pv.17 = or i1 %pv.15, %pv.16
  br i1 %pv.17, label %direct.18, label %decide.19
direct.18:
  %pslot.20 = getelementptr i64, ptr %clo.3, i64 1
  %real.22 = getelementptr i8, ptr %root.26, i64 0
  %real.21 = getelementptr i8, ptr %real.22, i64 0
  store ptr %real.21, ptr %pslot.20
  %pslot.27 = getelementptr i64, ptr %clo.3, i64 2
  %real.29 = getelementptr i8, ptr %root.33, i64 0
  %real.28 = getelementptr i8, ptr %real.29, i64 0
  store ptr %real.28, ptr %pslot.27
  call void %cv.7(ptr @sg_kernel_task1_private, ptr %clo.3, i64 %b.4, i64 %e.5, i64 455)
  br label %scatterdone.34
decide.19:
  %pv.10 = mul i64 %pv.14, 24
  %pv.11 = mul i64 %cv.9, 24
  %pv.12 = icmp sge i64 %pv.10, %pv.11
  %pv.35 = mul i64 %cv.9, 96
  %pv.36 = icmp ule i64 %pv.35, 268435456
  %pv.13 = and i1 %pv.12, %pv.36
  br i1 %pv.13, label %alloc.38, label %atomic.37
alloc.38:
  %ph.40 = getelementptr i64, ptr %ctx, i64 11
  %ph.41 = load ptr, ptr %ph.40
  %ph.42 = load ptr, ptr %ph.41
  %ph.43 = getelementptr i64, ptr %ph.41, i64 1
  %ph.44 = load i64, ptr %ph.43
  %ph.45 = mul i64 %cv.9, 64
  %ph.46 = icmp uge i64 %ph.44, %ph.45
  br i1 %ph.46, label %pready.48, label %pfresh.47
pfresh.47:
  call void @free(ptr %ph.42)
  %pnew.49 = call ptr @calloc(i64 %cv.9, i64 64)
  store ptr %pnew.49, ptr %ph.41
  %pnull.50 = icmp eq ptr %pnew.49, null
  %pcap.51 = select i1 %pnull.50, i64 0, i64 %ph.45
  store i64 %pcap.51, ptr %ph.43
  br label %pready.48
pready.48:
  %priv.52 = load ptr, ptr %ph.41
  %pslot.53 = getelementptr i64, ptr %clo.3, i64 1
  store ptr %priv.52, ptr %pslot.53
  %pnn.54 = icmp ne ptr %priv.52, null
  %pok.55 = and i1 true, %pnn.54
  %ph.56 = getelementptr i64, ptr %ctx, i64 12
  %ph.57 = load ptr, ptr %ph.56
  %ph.58 = load ptr, ptr %ph.57
  %ph.59 = getelementptr i64, ptr %ph.57, i64 1
  %ph.60 = load i64, ptr %ph.59
  %ph.61 = mul i64 %cv.9, 32
  %ph.62 = icmp uge i64 %ph.60, %ph.61
  br i1 %ph.62, label %pready.64, label %pfresh.63
pfresh.63:
  call void @free(ptr %ph.58)
  %pnew.65 = call ptr @calloc(i64 %cv.9, i64 32)
  store ptr %pnew.65, ptr %ph.57
  %pnull.66 = icmp eq ptr %pnew.65, null
  %pcap.67 = select i1 %pnull.66, i64 0, i64 %ph.61
  store i64 %pcap.67, ptr %ph.59
  br label %pready.64
pready.64:
  %priv.68 = load ptr, ptr %ph.57
  %pslot.69 = getelementptr i64, ptr %clo.3, i64 2
  store ptr %priv.68, ptr %pslot.69
  %pnn.70 = icmp ne ptr %priv.68, null
  %pok.71 = and i1 %pok.55, %pnn.70
  br i1 %pok.71, label %private.39, label %atomic.37
private.39:
  call void %cv.7(ptr @sg_kernel_task1_private, ptr %clo.3, i64 %b.4, i64 %e.5, i64 455)
  %real.73 = getelementptr i8, ptr %root.26, i64 0
  %real.72 = getelementptr i8, ptr %real.73, i64 0
  %sslot.75 = getelementptr i64, ptr %sclo.74, i64 0
  store ptr %priv.52, ptr %sslot.75
  %sslot.76 = getelementptr i64, ptr %sclo.74, i64 1
  store ptr %real.72, ptr %sslot.76
  %sslot.77 = getelementptr i64, ptr %sclo.74, i64 2
  store i64 %cv.9, ptr %sslot.77
  %sslot.78 = getelementptr i64, ptr %sclo.74, i64 3
  store i64 16, ptr %sslot.78
  call void %cv.7(ptr @sg_kernel_task1_private_sum0, ptr %sclo.74, i64 0, i64 16, i64 8192)
  %cancel.79 = load atomic i32, ptr %cv.2 monotonic, align 4
  %cancelled.80 = icmp ne i32 %cancel.79, 0
  br i1 %cancelled.80, label %psumhere.81, label %psumdone.82
psumhere.81:
  call void @sg_kernel_task1_private_sum0(ptr %sclo.74, i64 0, i64 16, i32 0)
  br label %psumdone.82
psumdone.82:
  %real.84 = getelementptr i8, ptr %root.33, i64 0
  %real.83 = getelementptr i8, ptr %real.84, i64 0
  %sslot.86 = getelementptr i64, ptr %sclo.85, i64 0
  store ptr %priv.68, ptr %sslot.86
  %sslot.87 = getelementptr i64, ptr %sclo.85, i64 1
  store ptr %real.83, ptr %sslot.87
  %sslot.88 = getelementptr i64, ptr %sclo.85, i64 2
  store i64 %cv.9, ptr %sslot.88
  %sslot.89 = getelementptr i64, ptr %sclo.85, i64 3
  store i64 8, ptr %sslot.89
  call void %cv.7(ptr @sg_kernel_task1_private_sum1, ptr %sclo.85, i64 0, i64 8, i64 8192)
  %cancel.90 = load atomic i32, ptr %cv.2 monotonic, align 4
  %cancelled.91 = icmp ne i32 %cancel.90, 0
  br i1 %cancelled.91, label %psumhere.92, label %psumdone.93
psumhere.92:
  call void @sg_kernel_task1_private_sum1(ptr %sclo.85, i64 0, i64 8, i32 0)
  br label %psumdone.93
psumdone.93:
  br label %scatterdone.34
atomic.37:
  call void %cv.7(ptr @sg_kernel_task1, ptr %clo.3, i64 %b.4, i64 %e.5, i64 455)
  br label %scatterdone.34
scatterdone.34:
  %cancel.94 = load atomic i32, ptr %cv.2 monotonic, align 4
  %cancelled.95 = icmp ne i32 %cancel.94, 0
  br i1 %cancelled.95, label %stop.96, label %go.97
stop.96:
  call void @sg_report(ptr %ctx, i64 -1, i64 0)
  ret void
go.97:
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

