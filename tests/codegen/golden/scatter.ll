declare noalias ptr @calloc(i64, i64)
declare void @free(ptr)
!0 = !{}
!900000 = distinct !{!900000, !"simgrad fields"}
!900002 = distinct !{!900002, !900000, !"page maps"}
!900003 = !{!900002}
!900004 = !{!900005, !900008, !900011}
!900005 = distinct !{!900005, !900000, !"tree 0 byte 0"}
!900006 = !{!900005}
!900007 = !{!900002, !900008, !900011}
!900008 = distinct !{!900008, !900000, !"tree 0 byte 4"}
!900009 = !{!900008}
!900010 = !{!900002, !900005, !900011}
!900011 = distinct !{!900011, !900000, !"tree 1 byte 0"}
!900012 = !{!900011}
!900013 = !{!900002, !900005, !900008}
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
  %pr.7 = getelementptr i64, ptr %clo, i64 3
  %pr.8 = load ptr, ptr %pr.7
  %pr.9 = mul i64 %pr.3, 64
  %pr.10 = getelementptr inbounds i8, ptr %pr.8, i64 %pr.9
  %pr.11 = sub i64 0, 0
  %pr.6 = getelementptr i8, ptr %pr.5, i64 %pr.11
  %pr.12 = getelementptr i64, ptr %clo, i64 2
  %pr.13 = load ptr, ptr %pr.12
  %pr.14 = zext i32 %tid to i64
  %pr.15 = mul i64 %pr.14, 64
  %pr.16 = getelementptr inbounds i8, ptr %pr.13, i64 %pr.15
  %pr.18 = getelementptr i64, ptr %clo, i64 4
  %pr.19 = load ptr, ptr %pr.18
  %pr.20 = mul i64 %pr.14, 64
  %pr.21 = getelementptr inbounds i8, ptr %pr.19, i64 %pr.20
  %pr.22 = sub i64 0, 0
  %pr.17 = getelementptr i8, ptr %pr.16, i64 %pr.22
  %lo.23 = trunc i64 %lo to i32
  %hi.24 = trunc i64 %hi to i32
  %red.25 = alloca float
  store float 0x0000000000000000, ptr %red.25
  %cp.61 = getelementptr i64, ptr %ctx, i64 0
  %cv.62 = load ptr, ptr %cp.61
  %rp.63 = getelementptr ptr, ptr %cv.62, i64 2
  %root.64 = load ptr, ptr %rp.63, !invariant.load !0, !dereferenceable !{i64 4}, !align !{i64 64}
  br label %pre.26
pre.26:
  br label %head.27
head.27:
  %i.31 = phi i32 [%lo.23, %pre.26], [%inext.32, %latch.29]
  %c.33 = icmp slt i32 %i.31, %hi.24
  br i1 %c.33, label %body.28, label %done.30
body.28:
  %v.34 = and i32 %i.31, 7
  %cv.35 = sext i32 %v.34 to i64
  %v.36 = mul nuw nsw i64 %cv.35, 8
  %ptr.37 = getelementptr i8, ptr %pr.6, i64 %v.36
  %pgo.38 = add i64 %v.36, %pr.11
  %pg.39 = lshr i64 %pgo.38, 12
  %pgm.40 = getelementptr inbounds i8, ptr %pr.10, i64 %pg.39
  store i8 1, ptr %pgm.40, !alias.scope !900003, !noalias !900004
  %old.41 = load float, ptr %ptr.37, !alias.scope !900006, !noalias !900007
  %new.42 = fadd nsz float %old.41, 0x3FF0000000000000
  store float %new.42, ptr %ptr.37, !alias.scope !900006, !noalias !900007
  %cv.43 = sext i32 %v.34 to i64
  %v.44 = mul nuw nsw i64 %cv.43, 8
  %v.45 = add nuw nsw i64 4, %v.44
  %ptr.46 = getelementptr i8, ptr %pr.6, i64 %v.45
  %pgo.47 = add i64 %v.45, %pr.11
  %pg.48 = lshr i64 %pgo.47, 12
  %pgm.49 = getelementptr inbounds i8, ptr %pr.10, i64 %pg.48
  store i8 1, ptr %pgm.49, !alias.scope !900003, !noalias !900004
  %old.50 = load float, ptr %ptr.46, !alias.scope !900009, !noalias !900010
  %new.51 = fadd nsz float %old.50, 0x4000000000000000
  store float %new.51, ptr %ptr.46, !alias.scope !900009, !noalias !900010
  %cv.52 = sext i32 %v.34 to i64
  %v.53 = mul nuw nsw i64 %cv.52, 4
  %ptr.54 = getelementptr i8, ptr %pr.17, i64 %v.53
  %pgo.55 = add i64 %v.53, %pr.22
  %pg.56 = lshr i64 %pgo.55, 12
  %pgm.57 = getelementptr inbounds i8, ptr %pr.21, i64 %pg.56
  store i8 1, ptr %pgm.57, !alias.scope !900003, !noalias !900004
  %old.58 = load float, ptr %ptr.54, !alias.scope !900012, !noalias !900013
  %new.59 = fadd nsz float %old.58, 0x3FF0000000000000
  store float %new.59, ptr %ptr.54, !alias.scope !900012, !noalias !900013
  %ptr.60 = getelementptr inbounds i8, ptr %root.64, i64 0
  %old.65 = load float, ptr %red.25
  %new.66 = fadd nsz float %old.65, 0x3FF0000000000000
  store float %new.66, ptr %red.25
  br label %latch.29
latch.29:
  %inext.32 = add i32 %i.31, 1
  br label %head.27
done.30:
  %sum.67 = load float, ptr %red.25
  %ptr.68 = getelementptr inbounds i8, ptr %root.64, i64 0
  %old.69 = atomicrmw fadd ptr %ptr.68, float %sum.67 monotonic
  ret void
}
define internal void @sg_kernel_task1_private_serial(ptr %clo, i64 %lo, i64 %hi, i32 %tid) {
entry:
  %ctx = load ptr, ptr %clo
  %pr.1 = getelementptr i64, ptr %clo, i64 1
  %pr.2 = load ptr, ptr %pr.1
  %pr.3 = zext i32 %tid to i64
  %pr.4 = mul i64 %pr.3, 64
  %pr.5 = getelementptr inbounds i8, ptr %pr.2, i64 %pr.4
  %pr.7 = getelementptr i64, ptr %clo, i64 3
  %pr.8 = load ptr, ptr %pr.7
  %pr.9 = mul i64 %pr.3, 64
  %pr.10 = getelementptr inbounds i8, ptr %pr.8, i64 %pr.9
  %pr.11 = sub i64 0, 0
  %pr.6 = getelementptr i8, ptr %pr.5, i64 %pr.11
  %pr.12 = getelementptr i64, ptr %clo, i64 2
  %pr.13 = load ptr, ptr %pr.12
  %pr.14 = zext i32 %tid to i64
  %pr.15 = mul i64 %pr.14, 64
  %pr.16 = getelementptr inbounds i8, ptr %pr.13, i64 %pr.15
  %pr.18 = getelementptr i64, ptr %clo, i64 4
  %pr.19 = load ptr, ptr %pr.18
  %pr.20 = mul i64 %pr.14, 64
  %pr.21 = getelementptr inbounds i8, ptr %pr.19, i64 %pr.20
  %pr.22 = sub i64 0, 0
  %pr.17 = getelementptr i8, ptr %pr.16, i64 %pr.22
  %lo.23 = trunc i64 %lo to i32
  %hi.24 = trunc i64 %hi to i32
  %red.25 = alloca float
  store float 0x0000000000000000, ptr %red.25
  %cp.52 = getelementptr i64, ptr %ctx, i64 0
  %cv.53 = load ptr, ptr %cp.52
  %rp.54 = getelementptr ptr, ptr %cv.53, i64 2
  %root.55 = load ptr, ptr %rp.54, !invariant.load !0, !dereferenceable !{i64 4}, !align !{i64 64}
  br label %pre.26
pre.26:
  br label %head.27
head.27:
  %i.31 = phi i32 [%lo.23, %pre.26], [%inext.32, %latch.29]
  %c.33 = icmp slt i32 %i.31, %hi.24
  br i1 %c.33, label %body.28, label %done.30
body.28:
  %v.34 = and i32 %i.31, 7
  %cv.35 = sext i32 %v.34 to i64
  %v.36 = mul nuw nsw i64 %cv.35, 8
  %ptr.37 = getelementptr i8, ptr %pr.6, i64 %v.36
  %old.38 = load float, ptr %ptr.37, !alias.scope !900006, !noalias !900007
  %new.39 = fadd nsz float %old.38, 0x3FF0000000000000
  store float %new.39, ptr %ptr.37, !alias.scope !900006, !noalias !900007
  %cv.40 = sext i32 %v.34 to i64
  %v.41 = mul nuw nsw i64 %cv.40, 8
  %v.42 = add nuw nsw i64 4, %v.41
  %ptr.43 = getelementptr i8, ptr %pr.6, i64 %v.42
  %old.44 = load float, ptr %ptr.43, !alias.scope !900009, !noalias !900010
  %new.45 = fadd nsz float %old.44, 0x4000000000000000
  store float %new.45, ptr %ptr.43, !alias.scope !900009, !noalias !900010
  %cv.46 = sext i32 %v.34 to i64
  %v.47 = mul nuw nsw i64 %cv.46, 4
  %ptr.48 = getelementptr i8, ptr %pr.17, i64 %v.47
  %old.49 = load float, ptr %ptr.48, !alias.scope !900012, !noalias !900013
  %new.50 = fadd nsz float %old.49, 0x3FF0000000000000
  store float %new.50, ptr %ptr.48, !alias.scope !900012, !noalias !900013
  %ptr.51 = getelementptr inbounds i8, ptr %root.55, i64 0
  %old.56 = load float, ptr %red.25
  %new.57 = fadd nsz float %old.56, 0x3FF0000000000000
  store float %new.57, ptr %red.25
  br label %latch.29
latch.29:
  %inext.32 = add i32 %i.31, 1
  br label %head.27
done.30:
  %sum.58 = load float, ptr %red.25
  %ptr.59 = getelementptr inbounds i8, ptr %root.55, i64 0
  %old.60 = atomicrmw fadd ptr %ptr.59, float %sum.58 monotonic
  ret void
}
define internal void @sg_kernel_task1_private_sum0(ptr %clo, i64 %lo, i64 %hi, i32 %tid) {
entry:
  %w0p = getelementptr i64, ptr %clo, i64 0
  %w0 = load ptr, ptr %w0p
  %w1p = getelementptr i64, ptr %clo, i64 1
  %w1 = load ptr, ptr %w1p
  %w2p = getelementptr i64, ptr %clo, i64 2
  %w2 = load i64, ptr %w2p
  %w3p = getelementptr i64, ptr %clo, i64 3
  %w3 = load i64, ptr %w3p
  %w4p = getelementptr i64, ptr %clo, i64 4
  %w4 = load ptr, ptr %w4p
  %w5p = getelementptr i64, ptr %clo, i64 5
  %w5 = load i64, ptr %w5p
  %w6p = getelementptr i64, ptr %clo, i64 6
  %w6 = load ptr, ptr %w6p
  %w7p = getelementptr i64, ptr %clo, i64 7
  %w7 = load i64, ptr %w7p
  br label %phead
phead:
  %p = phi i64 [%lo, %entry], [%pnext, %tdone]
  %seen = phi i64 [0, %entry], [%seen.t, %tdone]
  %pc = icmp slt i64 %p, %hi
  br i1 %pc, label %pbody, label %done
pbody:
  %k0 = mul i64 %p, 1024
  %kend = add i64 %k0, 1024
  %kfull = icmp slt i64 %kend, %w3
  %k1 = select i1 %kfull, i64 %kend, i64 %w3
  br label %thead
thead:
  %t = phi i64 [0, %pbody], [%tnext, %tnext.from]
  %seen.t = phi i64 [%seen, %pbody], [%seen.n, %tnext.from]
  %tc = icmp slt i64 %t, %w2
  br i1 %tc, label %tbody, label %tdone
tbody:
  %mrow = mul i64 %t, %w5
  %mat = add i64 %mrow, %p
  %mp = getelementptr inbounds i8, ptr %w4, i64 %mat
  %mark = load i8, ptr %mp
  %marked = icmp ne i8 %mark, 0
  br i1 %marked, label %tsum, label %tnext.from
tsum:
  store i8 0, ptr %mp
  %seen.s = add i64 %seen.t, 1
  %base = mul i64 %t, %w7
  %copy = getelementptr inbounds float, ptr %w0, i64 %base
  br label %khead
khead:
  %k = phi i64 [%k0, %tsum], [%knext, %kbody]
  %kc = icmp slt i64 %k, %k1
  br i1 %kc, label %kbody, label %tnext.from
kbody:
  %src = getelementptr inbounds float, ptr %copy, i64 %k
  %dst = getelementptr inbounds float, ptr %w1, i64 %k
  %part = load float, ptr %src
  %old = load float, ptr %dst
  %added = fadd float %old, %part
  %zero = fcmp oeq float %part, 0.0
  %new = select i1 %zero, float %old, float %added
  store float 0.0, ptr %src
  store float %new, ptr %dst
  %knext = add i64 %k, 1
  br label %khead
tnext.from:
  %seen.n = phi i64 [%seen.t, %tbody], [%seen.s, %khead]
  %tnext = add i64 %t, 1
  br label %thead
tdone:
  %pnext = add i64 %p, 1
  br label %phead
done:
  %old.seen = atomicrmw add ptr %w6, i64 %seen monotonic
  ret void
}
define internal void @sg_kernel_task1_private_sum1(ptr %clo, i64 %lo, i64 %hi, i32 %tid) {
entry:
  %w0p = getelementptr i64, ptr %clo, i64 0
  %w0 = load ptr, ptr %w0p
  %w1p = getelementptr i64, ptr %clo, i64 1
  %w1 = load ptr, ptr %w1p
  %w2p = getelementptr i64, ptr %clo, i64 2
  %w2 = load i64, ptr %w2p
  %w3p = getelementptr i64, ptr %clo, i64 3
  %w3 = load i64, ptr %w3p
  %w4p = getelementptr i64, ptr %clo, i64 4
  %w4 = load ptr, ptr %w4p
  %w5p = getelementptr i64, ptr %clo, i64 5
  %w5 = load i64, ptr %w5p
  %w6p = getelementptr i64, ptr %clo, i64 6
  %w6 = load ptr, ptr %w6p
  %w7p = getelementptr i64, ptr %clo, i64 7
  %w7 = load i64, ptr %w7p
  br label %phead
phead:
  %p = phi i64 [%lo, %entry], [%pnext, %tdone]
  %seen = phi i64 [0, %entry], [%seen.t, %tdone]
  %pc = icmp slt i64 %p, %hi
  br i1 %pc, label %pbody, label %done
pbody:
  %k0 = mul i64 %p, 1024
  %kend = add i64 %k0, 1024
  %kfull = icmp slt i64 %kend, %w3
  %k1 = select i1 %kfull, i64 %kend, i64 %w3
  br label %thead
thead:
  %t = phi i64 [0, %pbody], [%tnext, %tnext.from]
  %seen.t = phi i64 [%seen, %pbody], [%seen.n, %tnext.from]
  %tc = icmp slt i64 %t, %w2
  br i1 %tc, label %tbody, label %tdone
tbody:
  %mrow = mul i64 %t, %w5
  %mat = add i64 %mrow, %p
  %mp = getelementptr inbounds i8, ptr %w4, i64 %mat
  %mark = load i8, ptr %mp
  %marked = icmp ne i8 %mark, 0
  br i1 %marked, label %tsum, label %tnext.from
tsum:
  store i8 0, ptr %mp
  %seen.s = add i64 %seen.t, 1
  %base = mul i64 %t, %w7
  %copy = getelementptr inbounds float, ptr %w0, i64 %base
  br label %khead
khead:
  %k = phi i64 [%k0, %tsum], [%knext, %kbody]
  %kc = icmp slt i64 %k, %k1
  br i1 %kc, label %kbody, label %tnext.from
kbody:
  %src = getelementptr inbounds float, ptr %copy, i64 %k
  %dst = getelementptr inbounds float, ptr %w1, i64 %k
  %part = load float, ptr %src
  %old = load float, ptr %dst
  %added = fadd float %old, %part
  %zero = fcmp oeq float %part, 0.0
  %new = select i1 %zero, float %old, float %added
  store float 0.0, ptr %src
  store float %new, ptr %dst
  %knext = add i64 %k, 1
  br label %khead
tnext.from:
  %seen.n = phi i64 [%seen.t, %tbody], [%seen.s, %khead]
  %tnext = add i64 %t, 1
  br label %thead
tdone:
  %pnext = add i64 %p, 1
  br label %phead
done:
  %old.seen = atomicrmw add ptr %w6, i64 %seen monotonic
  ret void
}
define void @sg_kernel(ptr %ctx) {
entry:
  %cp.1 = getelementptr i64, ptr %ctx, i64 8
  %cv.2 = load ptr, ptr %cp.1
  store atomic i32 0, ptr %cv.2 monotonic, align 4
  %clo.3 = alloca [5 x i64], align 8
  %cp.6 = getelementptr i64, ptr %ctx, i64 3
  %cv.7 = load ptr, ptr %cp.6
  %cp.8 = getelementptr i64, ptr %ctx, i64 7
  %cv.9 = load i64, ptr %cp.8
  %cp.22 = getelementptr i64, ptr %ctx, i64 0
  %cv.23 = load ptr, ptr %cp.22
  %rp.24 = getelementptr ptr, ptr %cv.23, i64 0
  %root.25 = load ptr, ptr %rp.24, !invariant.load !0
  %cp.29 = getelementptr i64, ptr %ctx, i64 0
  %cv.30 = load ptr, ptr %cp.29
  %rp.31 = getelementptr ptr, ptr %cv.30, i64 1
  %root.32 = load ptr, ptr %rp.31, !invariant.load !0
  %sclo.145 = alloca [8 x i64], align 8
  %sclo.160 = alloca [8 x i64], align 8
  store ptr %ctx, ptr %clo.3
  %b.4 = sext i32 0 to i64
  %e.5 = sext i32 64 to i64
  %pv.13 = sub i64 %e.5, %b.4
  %pv.14 = icmp sle i64 %cv.9, 1
  %pv.15 = icmp sle i64 %pv.13, 455
  %pv.16 = or i1 %pv.14, %pv.15
  br i1 %pv.16, label %direct.17, label %decide.18
direct.17:
  %real.21 = getelementptr i8, ptr %root.25, i64 0
  %real.20 = getelementptr i8, ptr %real.21, i64 0
  %pslot.26 = getelementptr i64, ptr %clo.3, i64 1
  store ptr %real.20, ptr %pslot.26
  %real.28 = getelementptr i8, ptr %root.32, i64 0
  %real.27 = getelementptr i8, ptr %real.28, i64 0
  %pslot.33 = getelementptr i64, ptr %clo.3, i64 2
  store ptr %real.27, ptr %pslot.33
  call void %cv.7(ptr @sg_kernel_task1_private_serial, ptr %clo.3, i64 %b.4, i64 %e.5, i64 455)
  br label %scatterdone.34
decide.18:
  %ph.36 = getelementptr i64, ptr %ctx, i64 12
  %ph.37 = load ptr, ptr %ph.36
  %ph.35 = getelementptr i64, ptr %ph.37, i64 2
  %ph.39 = getelementptr i64, ptr %ctx, i64 14
  %ph.40 = load ptr, ptr %ph.39
  %ph.38 = getelementptr i64, ptr %ph.40, i64 2
  %pg.41 = load i64, ptr %ph.35
  %pg.42 = icmp sge i64 %pg.41, 0
  %pg.44 = mul i64 %cv.9, 1
  %pg.45 = udiv i64 %pg.44, 8
  %pg.43 = select i1 %pg.42, i64 %pg.41, i64 %pg.45
  %pg.46 = mul i64 %pg.43, 1024
  %pg.47 = load i64, ptr %ph.38
  %pg.48 = icmp sge i64 %pg.47, 0
  %pg.50 = mul i64 %cv.9, 1
  %pg.51 = udiv i64 %pg.50, 8
  %pg.49 = select i1 %pg.48, i64 %pg.47, i64 %pg.51
  %pg.52 = mul i64 %pg.49, 1024
  %pv.53 = add i64 0, %pg.46
  %pv.54 = add i64 %pv.53, %pg.52
  %pv.10 = mul i64 %pv.13, 24
  %pv.11 = icmp sge i64 %pv.10, %pv.54
  %pv.55 = mul i64 %cv.9, 96
  %pv.56 = icmp ule i64 %pv.55, 268435456
  %pv.12 = and i1 %pv.11, %pv.56
  br i1 %pv.12, label %alloc.57, label %atomic.19
alloc.57:
  %ph.58 = getelementptr i64, ptr %ctx, i64 11
  %ph.59 = load ptr, ptr %ph.58
  %ph.60 = load ptr, ptr %ph.59
  %ph.61 = getelementptr i64, ptr %ph.59, i64 1
  %ph.62 = load i64, ptr %ph.61
  %ph.63 = mul i64 %cv.9, 64
  %ph.64 = icmp uge i64 %ph.62, %ph.63
  br i1 %ph.64, label %pready.66, label %pfresh.65
pfresh.65:
  call void @free(ptr %ph.60)
  %pmore.70 = add i64 %ph.63, 64
  %pnew.67 = call ptr @calloc(i64 1, i64 %pmore.70)
  store ptr %pnew.67, ptr %ph.59
  %pnull.68 = icmp eq ptr %pnew.67, null
  %pcap.69 = select i1 %pnull.68, i64 0, i64 %ph.63
  store i64 %pcap.69, ptr %ph.61
  br label %pready.66
pready.66:
  %priv.71 = load ptr, ptr %ph.59
  %priv.72 = ptrtoint ptr %priv.71 to i64
  %priv.73 = add i64 %priv.72, 63
  %priv.74 = and i64 %priv.73, -64
  %priv.75 = inttoptr i64 %priv.74 to ptr
  %pslot.78 = getelementptr i64, ptr %clo.3, i64 1
  store ptr %priv.75, ptr %pslot.78
  %pnn.76 = icmp ne ptr %priv.75, null
  %pok.77 = and i1 true, %pnn.76
  %ph.79 = getelementptr i64, ptr %ctx, i64 12
  %ph.80 = load ptr, ptr %ph.79
  %ph.81 = load ptr, ptr %ph.80
  %ph.82 = getelementptr i64, ptr %ph.80, i64 1
  %ph.83 = load i64, ptr %ph.82
  %ph.84 = mul i64 %cv.9, 64
  %ph.85 = icmp uge i64 %ph.83, %ph.84
  br i1 %ph.85, label %pready.87, label %pfresh.86
pfresh.86:
  call void @free(ptr %ph.81)
  %pmore.91 = add i64 %ph.84, 64
  %pnew.88 = call ptr @calloc(i64 1, i64 %pmore.91)
  store ptr %pnew.88, ptr %ph.80
  %pnull.89 = icmp eq ptr %pnew.88, null
  %pcap.90 = select i1 %pnull.89, i64 0, i64 %ph.84
  store i64 %pcap.90, ptr %ph.82
  br label %pready.87
pready.87:
  %priv.92 = load ptr, ptr %ph.80
  %priv.93 = ptrtoint ptr %priv.92 to i64
  %priv.94 = add i64 %priv.93, 63
  %priv.95 = and i64 %priv.94, -64
  %priv.96 = inttoptr i64 %priv.95 to ptr
  %pslot.99 = getelementptr i64, ptr %clo.3, i64 3
  store ptr %priv.96, ptr %pslot.99
  %pnn.97 = icmp ne ptr %priv.96, null
  %pok.98 = and i1 %pok.77, %pnn.97
  %ph.100 = getelementptr i64, ptr %ctx, i64 13
  %ph.101 = load ptr, ptr %ph.100
  %ph.102 = load ptr, ptr %ph.101
  %ph.103 = getelementptr i64, ptr %ph.101, i64 1
  %ph.104 = load i64, ptr %ph.103
  %ph.105 = mul i64 %cv.9, 64
  %ph.106 = icmp uge i64 %ph.104, %ph.105
  br i1 %ph.106, label %pready.108, label %pfresh.107
pfresh.107:
  call void @free(ptr %ph.102)
  %pmore.112 = add i64 %ph.105, 64
  %pnew.109 = call ptr @calloc(i64 1, i64 %pmore.112)
  store ptr %pnew.109, ptr %ph.101
  %pnull.110 = icmp eq ptr %pnew.109, null
  %pcap.111 = select i1 %pnull.110, i64 0, i64 %ph.105
  store i64 %pcap.111, ptr %ph.103
  br label %pready.108
pready.108:
  %priv.113 = load ptr, ptr %ph.101
  %priv.114 = ptrtoint ptr %priv.113 to i64
  %priv.115 = add i64 %priv.114, 63
  %priv.116 = and i64 %priv.115, -64
  %priv.117 = inttoptr i64 %priv.116 to ptr
  %pslot.120 = getelementptr i64, ptr %clo.3, i64 2
  store ptr %priv.117, ptr %pslot.120
  %pnn.118 = icmp ne ptr %priv.117, null
  %pok.119 = and i1 %pok.98, %pnn.118
  %ph.121 = getelementptr i64, ptr %ctx, i64 14
  %ph.122 = load ptr, ptr %ph.121
  %ph.123 = load ptr, ptr %ph.122
  %ph.124 = getelementptr i64, ptr %ph.122, i64 1
  %ph.125 = load i64, ptr %ph.124
  %ph.126 = mul i64 %cv.9, 64
  %ph.127 = icmp uge i64 %ph.125, %ph.126
  br i1 %ph.127, label %pready.129, label %pfresh.128
pfresh.128:
  call void @free(ptr %ph.123)
  %pmore.133 = add i64 %ph.126, 64
  %pnew.130 = call ptr @calloc(i64 1, i64 %pmore.133)
  store ptr %pnew.130, ptr %ph.122
  %pnull.131 = icmp eq ptr %pnew.130, null
  %pcap.132 = select i1 %pnull.131, i64 0, i64 %ph.126
  store i64 %pcap.132, ptr %ph.124
  br label %pready.129
pready.129:
  %priv.134 = load ptr, ptr %ph.122
  %priv.135 = ptrtoint ptr %priv.134 to i64
  %priv.136 = add i64 %priv.135, 63
  %priv.137 = and i64 %priv.136, -64
  %priv.138 = inttoptr i64 %priv.137 to ptr
  %pslot.141 = getelementptr i64, ptr %clo.3, i64 4
  store ptr %priv.138, ptr %pslot.141
  %pnn.139 = icmp ne ptr %priv.138, null
  %pok.140 = and i1 %pok.119, %pnn.139
  br i1 %pok.140, label %private.142, label %atomic.19
private.142:
  call void %cv.7(ptr @sg_kernel_task1_private, ptr %clo.3, i64 %b.4, i64 %e.5, i64 455)
  %real.144 = getelementptr i8, ptr %root.25, i64 0
  %real.143 = getelementptr i8, ptr %real.144, i64 0
  store i64 0, ptr %ph.35
  %pslot.146 = getelementptr i64, ptr %sclo.145, i64 0
  store ptr %priv.75, ptr %pslot.146
  %pslot.147 = getelementptr i64, ptr %sclo.145, i64 1
  store ptr %real.143, ptr %pslot.147
  %pslot.148 = getelementptr i64, ptr %sclo.145, i64 2
  store i64 %cv.9, ptr %pslot.148
  %pslot.149 = getelementptr i64, ptr %sclo.145, i64 3
  store i64 16, ptr %pslot.149
  %pslot.150 = getelementptr i64, ptr %sclo.145, i64 4
  store ptr %priv.96, ptr %pslot.150
  %pslot.151 = getelementptr i64, ptr %sclo.145, i64 5
  store i64 64, ptr %pslot.151
  %pslot.152 = getelementptr i64, ptr %sclo.145, i64 6
  store ptr %ph.35, ptr %pslot.152
  %pslot.153 = getelementptr i64, ptr %sclo.145, i64 7
  store i64 16, ptr %pslot.153
  call void %cv.7(ptr @sg_kernel_task1_private_sum0, ptr %sclo.145, i64 0, i64 1, i64 8)
  %cancel.154 = load atomic i32, ptr %cv.2 monotonic, align 4
  %cancelled.155 = icmp ne i32 %cancel.154, 0
  br i1 %cancelled.155, label %psumhere.156, label %psumdone.157
psumhere.156:
  call void @sg_kernel_task1_private_sum0(ptr %sclo.145, i64 0, i64 1, i32 0)
  br label %psumdone.157
psumdone.157:
  %real.159 = getelementptr i8, ptr %root.32, i64 0
  %real.158 = getelementptr i8, ptr %real.159, i64 0
  store i64 0, ptr %ph.38
  %pslot.161 = getelementptr i64, ptr %sclo.160, i64 0
  store ptr %priv.117, ptr %pslot.161
  %pslot.162 = getelementptr i64, ptr %sclo.160, i64 1
  store ptr %real.158, ptr %pslot.162
  %pslot.163 = getelementptr i64, ptr %sclo.160, i64 2
  store i64 %cv.9, ptr %pslot.163
  %pslot.164 = getelementptr i64, ptr %sclo.160, i64 3
  store i64 8, ptr %pslot.164
  %pslot.165 = getelementptr i64, ptr %sclo.160, i64 4
  store ptr %priv.138, ptr %pslot.165
  %pslot.166 = getelementptr i64, ptr %sclo.160, i64 5
  store i64 64, ptr %pslot.166
  %pslot.167 = getelementptr i64, ptr %sclo.160, i64 6
  store ptr %ph.38, ptr %pslot.167
  %pslot.168 = getelementptr i64, ptr %sclo.160, i64 7
  store i64 16, ptr %pslot.168
  call void %cv.7(ptr @sg_kernel_task1_private_sum1, ptr %sclo.160, i64 0, i64 1, i64 8)
  %cancel.169 = load atomic i32, ptr %cv.2 monotonic, align 4
  %cancelled.170 = icmp ne i32 %cancel.169, 0
  br i1 %cancelled.170, label %psumhere.171, label %psumdone.172
psumhere.171:
  call void @sg_kernel_task1_private_sum1(ptr %sclo.160, i64 0, i64 1, i32 0)
  br label %psumdone.172
psumdone.172:
  br label %scatterdone.34
atomic.19:
  %pc.173 = load i64, ptr %ph.35
  %pc.174 = sdiv i64 %pc.173, 64
  %pc.175 = sub i64 %pc.173, %pc.174
  store i64 %pc.175, ptr %ph.35
  %pc.176 = load i64, ptr %ph.38
  %pc.177 = sdiv i64 %pc.176, 64
  %pc.178 = sub i64 %pc.176, %pc.177
  store i64 %pc.178, ptr %ph.38
  call void %cv.7(ptr @sg_kernel_task1, ptr %clo.3, i64 %b.4, i64 %e.5, i64 455)
  br label %scatterdone.34
scatterdone.34:
  %cancel.179 = load atomic i32, ptr %cv.2 monotonic, align 4
  %cancelled.180 = icmp ne i32 %cancel.179, 0
  br i1 %cancelled.180, label %stop.181, label %go.182
stop.181:
  call void @sg_report(ptr %ctx, i64 -1, i64 0)
  ret void
go.182:
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

