; sfwd:750:8 (benchmarks/fuzz_long.py --gen shapes), the task function after simgrad's -O3 pipeline with loop unrolling,
; reduced (definitions replaced by poison while the crash stays). LLVM 22.1 (llvmlite 0.50.0, assertions on)
; aborts in X86 instruction selection: cast<MemSDNode>(SDNode*) assertion. Emit it with llvmlite:
;   tm = Target.from_default_triple().create_target_machine(opt=3); tm.emit_object(parse_assembly(text))
; opt=0 emits it; opt=1..3 abort (cpu generic or znver5). Note %g.155 and %g.136 load the same address
; ((v & 3) << 2 and (v << 2) & 12) and %sel.176 selects between %g.155 and a load of the base.
; ModuleID = '<string>'
source_filename = "<string>"

; Function Attrs: mustprogress nocallback nocreateundeforpoison nofree nosync nounwind speculatable willreturn memory(none)
declare double @llvm.floor.f64(double) #0

; Function Attrs: mustprogress nocallback nocreateundeforpoison nofree nosync nounwind speculatable willreturn memory(none)
declare i32 @llvm.smax.i32(i32, i32) #0

; Function Attrs: nofree norecurse nosync nounwind memory(readwrite, inaccessiblemem: none, target_mem0: none, target_mem1: none)
define void @sg_kernel_task1(ptr readonly captures(none) %clo, i64 %lo, i64 %hi, i32 %tid) #1 {
entry:
  %root.30 = load ptr, ptr poison, align 8, !invariant.load !0
  br i1 poison, label %body.5.preheader, label %done.7

body.5.preheader:                                 ; preds = %entry
  br label %body.5

body.5:                                           ; preds = %body.5.preheader, %done.115
  %g.31 = load i32, ptr poison, align 4
  %g.67 = load i32, ptr poison, align 4
  %m.87 = srem i32 %g.67, 5
  %t.93 = select i1 poison, i32 5, i32 0
  %v.81 = add nsw i32 %m.87, 6
  %v.94 = add nuw nsw i32 %v.81, %t.93
  %m.101 = srem i32 %g.31, %v.94
  %t.103 = icmp slt i32 %m.101, 0
  %t.107 = select i1 %t.103, i32 %v.94, i32 0
  %v.95 = add nsw i32 %t.107, %m.101
  %v.139 = and i32 %v.95, 3
  %cv.152 = zext nneg i32 %v.139 to i64
  %v.153 = shl nuw nsw i64 %cv.152, 2
  %ptr.154 = getelementptr inbounds nuw i8, ptr %root.30, i64 %v.153
  %g.155 = load i32, ptr %ptr.154, align 4
  %v.120 = shl nsw i32 %v.95, 2
  %1 = and i32 %v.120, 12
  %v.134 = zext nneg i32 %1 to i64
  %ptr.135 = getelementptr inbounds nuw i8, ptr %root.30, i64 %v.134
  %g.136 = load i32, ptr %ptr.135, align 4
  %cmp.138 = icmp eq i32 %g.136, 0
  %g.172 = load i32, ptr %root.30, align 4
  %sel.176 = select i1 %cmp.138, i32 %g.155, i32 %g.172
  %g.180 = load double, ptr poison, align 8
  %var.185.0 = select i1 poison, double poison, double %g.180
  %cmp.197 = fcmp ogt double %var.185.0, -3.650000e-01
  %2 = sitofp i32 %g.155 to double
  %cv.250 = select i1 %cmp.197, double %2, double 0.000000e+00
  %v.251 = fsub nsz double %cv.250, %g.180
  %cmp.253 = fcmp olt double %g.180, %v.251
  %m.347 = srem i32 %sel.176, 3
  %cmp.3556 = icmp eq i32 %m.347, 0
  %or.cond = select i1 %cmp.253, i1 true, i1 %cmp.3556
  br i1 %or.cond, label %done.115, label %head.112

head.112:                                         ; preds = %body.5
  br i1 poison, label %then.257.1, label %endif.259.1

then.257.1:                                       ; preds = %head.112
  br label %endif.259.1

endif.259.1:                                      ; preds = %then.257.1, %head.112
  br i1 poison, label %done.115, label %head.112.1

head.112.1:                                       ; preds = %endif.259.1
  br i1 poison, label %then.257.2, label %endif.259.2

then.257.2:                                       ; preds = %head.112.1
  br label %endif.259.2

endif.259.2:                                      ; preds = %then.257.2, %head.112.1
  br label %done.115

done.115:                                         ; preds = %endif.259.2, %body.5, %endif.259.1
  br i1 poison, label %body.5, label %done.7

done.7:                                           ; preds = %done.115, %entry
  ret void
}


; Function Attrs: mustprogress nofree noinline norecurse nounwind willreturn memory(argmem: readwrite)

attributes #0 = { mustprogress nocallback nocreateundeforpoison nofree nosync nounwind speculatable willreturn memory(none) }
attributes #1 = { nofree norecurse nosync nounwind memory(readwrite, inaccessiblemem: none, target_mem0: none, target_mem1: none) }
attributes #2 = { mustprogress nofree noinline norecurse nounwind willreturn memory(argmem: readwrite) }

!0 = !{}
